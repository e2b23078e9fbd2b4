"""Locomotion by speed (issue 14, item 2): a locomotion set (idle, walk, run) played by the
speed asked for, cross-faded at matching foot phases, never with a foot sliding."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from ecs_anim.components import MotionPlayer
from ecs_anim.core.ground import Bumps
from ecs_anim.core.morphology import Morphology
from ecs_anim.io.library import MOTIONS_DIR
from ecs_anim.io.library.shipped import main as library_main
from ecs_anim.motion.clip import NormalizedMotion
from ecs_anim.runtime.metrics import MetricsRecorder
from ecs_anim.runtime.simulation import Simulation
from ecs_anim.runtime.steering import IDLE, RUN, WALK
from ecs_anim.scenario import build_simulation, load_scenario

STATURES = (1.20, 1.75, 2.00)
BUMPS = Bumps(amplitude_m=0.03, wavelength_x_m=2.5, wavelength_y_m=3.0)


def joint_speeds(positions: np.ndarray, fps: float) -> np.ndarray:
    """(ticks - 1, n, joints) each joint's speed between ticks, m/s."""
    speeds: np.ndarray = np.linalg.norm(np.diff(positions, axis=0), axis=-1) * fps
    return speeds


def run_clip_joint_speed(motions: dict[str, NormalizedMotion]) -> np.ndarray:
    """(n,) the fastest joint of the run clip played as captured on each body, m/s."""
    sim = Simulation(motions, BUMPS)
    for stature in STATURES:
        sim.spawn(f"s{stature}", Morphology.from_stature(stature), MotionPlayer("run"))
    positions = []
    for _ in range(round(4 * sim.fps)):
        sim.step()
        positions.append(sim.store.positions.copy())
    fastest: np.ndarray = joint_speeds(np.array(positions)[5:], sim.fps).max(axis=(0, 2))
    return fastest


def test_the_library_has_a_run_and_is_up_to_date(motions: dict[str, NormalizedMotion]) -> None:
    assert library_main(["--check"]) == 0
    run = motions["run"]
    weights = np.zeros((run.n_frames, 2))
    t = np.arange(run.n_frames) / run.fps
    for c in run.constraints:
        if c.kind == "foot_contact":
            side = 0 if c.segment.endswith("_l") else 1
            weights[:, side] = np.maximum(weights[:, side], c.activation.weight(t, smooth=False))
    assert np.any(weights.max(axis=1) == 0.0)  # flight: both feet up
    assert 0.25 < np.mean(weights[:, 0] > 0) < 0.5


def test_speed_ramp_idle_walk_run_walk_idle(motions: dict[str, NormalizedMotion]) -> None:
    sim = Simulation(motions, BUMPS)
    # The bodies start on one spot: steering alone, without avoiding each other.
    sim.steering_settings = replace(sim.steering_settings, avoidance=False)
    entities = [sim.spawn(f"s{stature}", Morphology.from_stature(stature), MotionPlayer("idle"))
                for stature in STATURES]
    for e in entities:
        sim.set_locomotion(e, walk="walk", idle="idle", run="run")
    gaits = sim.gait_table()
    run_own = gaits.speed_legs_s[sim.bank.index("run")] * sim.leg_length()

    def fraction_of_run(t: float) -> float:  # stand 2 s, up to the run's speed, hold, down, stand
        return float(np.interp(t, [0, 2, 9, 12, 19, 24], [0, 0, 1, 1, 0, 0]))

    metrics = MetricsRecorder(sim)
    positions, gait, weight, locked, footprint, pivot = [], [], [], [], [], []
    for tick in range(round(24 * sim.fps)):
        for k, e in enumerate(entities):
            sim.steer(e, heading_rad=0.3, speed_m_s=fraction_of_run(tick / sim.fps) * run_own[k])
        sim.step()
        metrics.record()
        st = sim.store
        positions.append(st.positions.copy())
        gait.append(st.gait.copy())
        weight.append(st.contact_weight.copy())
        locked.append(st.locked.copy())
        footprint.append(st.footprint.copy())
        pivot.append(st.pivot.copy())
    report = metrics.report()
    gait_, weight_, locked_, footprint_, pivot_ = map(np.array, (gait, weight, locked, footprint,
                                                                 pivot))
    fastest = joint_speeds(np.array(positions), sim.fps).max(axis=(0, 2))
    own = run_clip_joint_speed(motions)
    for k, stature in enumerate(STATURES):
        switches = np.flatnonzero(np.diff(gait_[:, k])) + 1
        assert [int(gait_[0, k])] + gait_[switches, k].tolist() == [IDLE, WALK, RUN, WALK, IDLE]
        c = report["characters"][k]
        assert c["foot_sliding_mm_per_frame"]["max"] < 1.0, (stature, c)
        assert c["ground_penetration_mm_max"] < 0.5, (stature, c)
        # No joint faster than the run's own fastest (the walk's rate is capped below that).
        assert fastest[k] <= own[k], (stature, fastest[k], own[k])
        # Walk <-> run: switched while a foot is down in both clips (the fade's contact weight
        # is the lesser of the two), and that foot keeps the footprint it had (not laid anew)
        # until one of the clips lifts it or it rolls from its heel onto its ball.
        for s in switches[1:3]:
            feet = np.flatnonzero((weight_[s, k] >= 1.0) & locked_[s - 1, k])
            assert feet.size, (stature, s)
            foot = feet[0]
            kept = s + int(np.argmax(~locked_[s:, k, foot]
                                     | (pivot_[s:, k, foot] != pivot_[s - 1, k, foot])))
            held = footprint_[s - 1:kept, k, foot]
            assert kept > s and np.abs(held - held[0]).max() < 1e-12
    assert report["slide_events"]["count"] == 0


def test_locomotion_and_speed_in_a_scenario(tmp_path: Path) -> None:
    path = tmp_path / "jog.yaml"
    path.write_text(f"""duration_s: 6
motions:
  idle: {MOTIONS_DIR / 'idle.bvh'}
  walk: {MOTIONS_DIR / 'walk.bvh'}
  run: {MOTIONS_DIR / 'run.bvh'}
characters:
  - name: jogger
    morphology: adult_male
    heading_deg: 90
    locomotion: {{idle: idle, walk: walk, run: run}}
    speed_m_s: 2.2
  - name: stander
    morphology: adult_female
    position_m: [2, 0]
    locomotion: {{idle: idle, walk: walk}}
""")
    scenario = load_scenario(path)
    with build_simulation(scenario) as sim:
        pelvis = []
        for _ in range(round(scenario.duration_s * scenario.fps)):
            sim.step()
            pelvis.append(sim.store.positions[:, 0, :2].copy())
        xy = np.array(pelvis)
        assert sim.store.gait.tolist() == [RUN, IDLE]
        moved = xy[-1, 0] - xy[-round(2 * sim.fps), 0]  # the last 2 s, at speed
        assert np.linalg.norm(moved) / 2.0 == pytest.approx(2.2, abs=0.1)
        assert moved[1] / np.linalg.norm(moved) > np.cos(np.radians(8))  # north
        assert np.linalg.norm(xy[-1, 1] - xy[0, 1]) < 0.05  # the stander stands
