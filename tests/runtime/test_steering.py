"""Steering (issue 14, item 1): characters follow paths, walk to goals, take a heading and speed,
by turning their motion's global heading about the planted foot (docs/steering.md)."""

from __future__ import annotations

import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from conftest import REPO, SCENARIOS_DIR
from ecs_anim.components import MotionPlayer, Placement
from ecs_anim.core.errors import EcsAnimError, InputError
from ecs_anim.core.ground import Bumps, Plane
from ecs_anim.core.morphology import Morphology
from ecs_anim.io.library import MOTIONS_DIR
from ecs_anim.motion.clip import NormalizedMotion
from ecs_anim.runtime.metrics import MetricsRecorder
from ecs_anim.runtime.simulation import Simulation
from ecs_anim.scenario import build_simulation, load_scenario
from ecs_anim.systems import MotionPlayback
from support.paths import distance_to_polyline

BUMPS = Bumps(amplitude_m=0.03, wavelength_x_m=2.5, wavelength_y_m=3.0)


def figure_eight(radius_m: float = 1.5, per_loop: int = 32) -> np.ndarray:
    """Waypoints (2 * per_loop, 2) of two circles touching at the origin, anticlockwise above
    the x axis then clockwise below it, back to the origin (where the character starts)."""
    a = np.linspace(0.0, 2 * np.pi, per_loop + 1)[1:]
    above = np.stack([radius_m * np.sin(a), radius_m * (1 - np.cos(a))], axis=1)
    below = np.stack([radius_m * np.sin(a), -radius_m * (1 - np.cos(a))], axis=1)
    return np.concatenate([above, below])


def walkers(motions: dict[str, NormalizedMotion], statures: tuple[float, ...],
            ground: object = BUMPS) -> tuple[Simulation, list[int]]:
    sim = Simulation(motions, ground)  # type: ignore[arg-type]
    # The bodies start on one spot: steering alone, without avoiding each other.
    sim.steering_settings = replace(sim.steering_settings, avoidance=False)
    entities = [sim.spawn(f"s{stature:.2f}", Morphology.from_stature(stature),
                          MotionPlayer("idle")) for stature in statures]
    for e in entities:
        sim.set_locomotion(e, walk="walk", idle="idle")
    return sim, entities


def own_peak_pelvis_speed(motions: dict[str, NormalizedMotion], statures: tuple[float, ...]) -> np.ndarray:
    """(n,) the walk's own peak horizontal pelvis speed on each body, played straight, m/s."""
    sim = Simulation(motions, BUMPS)
    for stature in statures:
        sim.spawn(f"s{stature:.2f}", Morphology.from_stature(stature), MotionPlayer("walk"))
    pelvis = []
    for _ in range(150):
        sim.step()
        pelvis.append(sim.store.positions[:, 0, :2].copy())
    speed = np.linalg.norm(np.diff(np.array(pelvis)[5:], axis=0), axis=-1) * sim.fps
    peak: np.ndarray = speed.max(axis=0)
    return peak


def test_figure_eight_over_bumps_child_and_tall(motions: dict[str, NormalizedMotion]) -> None:
    statures = (1.20, 2.00)
    sim, entities = walkers(motions, statures)
    path = figure_eight()
    for e in entities:
        sim.follow_path(e, path)
    metrics = MetricsRecorder(sim)
    pelvis = []
    for _ in range(round(28 * sim.fps)):
        sim.step()
        metrics.record()
        pelvis.append(sim.store.positions[:, 0, :2].copy())
    xy = np.array(pelvis)
    report = metrics.report()
    line = np.concatenate([[[0.0, 0.0]], path])
    peak = own_peak_pelvis_speed(motions, statures)
    for k, e in enumerate(entities):
        off_path = distance_to_polyline(xy[:, k], line)
        assert off_path.max() < 0.25, (statures[k], off_path.max())
        c = report["characters"][k]
        assert c["foot_sliding_mm_per_frame"]["max"] < 1.0, c
        assert c["ground_penetration_mm_max"] < 0.5, c  # no sole below the ground
        speed = np.linalg.norm(np.diff(xy[:, k], axis=0), axis=-1) * sim.fps
        assert speed.max() <= 1.2 * peak[k], (statures[k], speed.max(), peak[k])
        assert sim.arrived(e)
        assert np.linalg.norm(xy[-1, k] - path[-1]) < 0.3, (statures[k], xy[-1, k])
        assert sim.store.gait[k] == 0  # stopped on its idle motion
    assert report["slide_events"]["count"] == 0


def test_a_goal_behind_is_turned_to_on_the_spot(motions: dict[str, NormalizedMotion]) -> None:
    statures = (1.20, 2.00)
    sim, entities = walkers(motions, statures, Plane())
    for _ in range(15):
        sim.step()
    start = sim.store.positions[:, 0, :2].copy()
    for e in entities:
        sim.walk_to(e, (-3.0, 0.5))  # they face +x: the goal is behind
    metrics = MetricsRecorder(sim)
    pelvis, heading = [], []
    for _ in range(round(10 * sim.fps)):
        sim.step()
        metrics.record()
        pelvis.append(sim.store.positions[:, 0, :2].copy())
        heading.append(sim.store.placement_heading.copy())
    xy, turned = np.array(pelvis), np.abs(np.angle(np.exp(1j * np.array(heading))))
    leg = sim.leg_length()
    for k, e in enumerate(entities):
        quarter = int(np.flatnonzero(turned[:, k] > np.pi / 2)[0])
        # A quarter turn within 1 s, the pelvis within 0.7 leg lengths of where it stood.
        assert quarter < sim.fps
        assert np.linalg.norm(xy[quarter, k] - start[k]) < 0.7 * leg[k]
        assert sim.arrived(e)
        assert np.linalg.norm(xy[-1, k] - (-3.0, 0.5)) < 0.3
        assert metrics.report()["characters"][k]["foot_sliding_mm_per_frame"]["max"] < 1.0


def test_steer_by_heading_and_speed_from_code(motions: dict[str, NormalizedMotion]) -> None:
    sim, (e,) = walkers(motions, (1.75,), Plane())
    metrics = MetricsRecorder(sim)
    pelvis = []
    for tick in range(round(8 * sim.fps)):
        sim.steer(e, heading_rad=np.pi / 2 if tick < 4 * sim.fps else np.pi, speed_m_s=1.0)
        sim.step()
        metrics.record()
        pelvis.append(sim.store.positions[0, 0, :2].copy())
    xy = np.array(pelvis)
    # Heading north at 1 m/s over seconds 2-4, then west over seconds 6-8.
    for (a, b), direction in (((2, 4), (0.0, 1.0)), ((6, 8), (-1.0, 0.0))):
        moved = xy[int(b * sim.fps) - 1] - xy[int(a * sim.fps)]
        assert np.linalg.norm(moved) / (b - a) == pytest.approx(1.0, abs=0.05)
        cosine = moved @ np.array(direction) / np.linalg.norm(moved)
        assert cosine > np.cos(np.radians(8))
    assert metrics.report()["characters"][0]["foot_sliding_mm_per_frame"]["max"] < 1.0
    sim.steer(e, speed_m_s=0.0)
    for _ in range(60):
        sim.step()
    assert sim.store.gait[0] == 0


def test_steering_equals_its_numpy_reference(motions: dict[str, NormalizedMotion]) -> None:
    def make() -> Simulation:
        sim = Simulation(motions, BUMPS)
        rng = np.random.default_rng(1401)
        for k in range(6):
            e = sim.spawn(f"c{k}", Morphology.from_stature(float(rng.uniform(1.1, 2.0))),
                          MotionPlayer("idle"), Placement((float(rng.uniform(-3, 3)),
                                                           float(rng.uniform(-3, 3)))))
            sim.set_locomotion(e, walk="walk", idle="idle", run="run")
            if k % 2:
                sim.follow_path(e, rng.uniform(-4, 4, (3, 2)), float(rng.uniform(0.5, 3.0)))
            else:
                sim.steer(e, float(rng.uniform(-3, 3)), float(rng.uniform(0.0, 3.0)))
        return sim

    # The compiled playback's sines and arc cosines are polynomials within 4e-16 of numpy's
    # (docs/performance.md, "Kernels on the vector units"): the two agree to about 1e-15 a
    # tick, until a walker's discrete choice (a gait, a velocity of avoidance at the edge of
    # its cone) falls the other way on such a rounding and their paths part: this seed's at
    # tick 68. Until then every joint is within 1e-12 m and every gait the same.
    compiled, reference = make(), make()
    system = next(s for s in reference.systems if isinstance(s, MotionPlayback))
    system.run = system.run_numpy  # type: ignore[method-assign]
    gaits = set()
    for tick in range(150):
        compiled.step()
        reference.step()
        gaits |= set(compiled.store.gait.tolist())
        apart = np.abs(compiled.store.positions - reference.store.positions).max()
        if apart > 1e-9:
            assert tick >= 60, (tick, apart)
            break
        assert apart < 1e-12, (tick, apart)
        np.testing.assert_array_equal(compiled.store.gait, reference.store.gait)
    assert gaits >= {1, 2}


def test_bad_paths_and_speeds_are_refused(motions: dict[str, NormalizedMotion]) -> None:
    sim, (e,) = walkers(motions, (1.75,), Plane())
    for path, message in ((np.zeros((0, 2)), "1 to 127 waypoints"),
                          (np.array([[0.0, np.nan]]), "finite"),
                          (np.array([1.0, 2.0]), r"list of \[x, y\] points")):
        with pytest.raises(EcsAnimError, match=message):
            sim.follow_path(e, path)
    with pytest.raises(EcsAnimError, match="speed_m_s"):
        sim.steer(e, 0.0, -1.0)
    with pytest.raises(EcsAnimError, match="does not travel"):
        sim.set_locomotion(e, walk="idle")
    with pytest.raises(EcsAnimError, match="unknown clip 'wlak'"):
        sim.set_locomotion(e, walk="wlak")
    standing = sim.spawn("standing", Morphology.preset("adult_male"), MotionPlayer("idle"))
    with pytest.raises(EcsAnimError, match="does not travel; give it a locomotion set"):
        sim.walk_to(standing, (1.0, 1.0))


SCENARIO_HEAD = f"""duration_s: 2
motions:
  idle: {MOTIONS_DIR / 'idle.bvh'}
  walk: {MOTIONS_DIR / 'walk.bvh'}
characters:
  - name: a
    morphology: adult_male
"""


@pytest.mark.parametrize(("lines", "line", "message"), [
    ("    locomotion: {idle: idle, walk: walk}\n    path_m: []\n", 9,
     "characters[0].path_m: a path needs at least 1 waypoint"),
    ("    locomotion: {walk: walk}\n    path_m: [[1, 1]]\n", 8,
     "characters[0].locomotion: a character given path_m stops on its idle motion"),
    ("    locomotion: {idle: idle, walk: idle}\n", 8,
     "characters[0].locomotion.walk: motion 'idle' does not travel"),
    ("    locomotion: {idle: idle, walk: wlak}\n", 8,
     "unknown motion 'wlak'; did you mean 'walk'?"),
    ("    path_m: [[1, 1]]\n", 8, "characters[0].path_m: a steered character needs a locomotion"),
    ("    locomotion: {idle: idle, walk: walk}\n    path_m: [[1, 1, 0]]\n", 9,
     "characters[0].path_m[0]: expected a list of 2 numbers"),
    ("    locomotion: {idle: idle, walk: walk}\n    path_m: [[1000, 1]]\n", 9,
     "was it given in mm?"),
    ("    locomotion: {idle: idle, walk: walk}\n    speed_m_s: -1\n", 9, "speed_m_s"),
])
def test_bad_steering_keys_are_one_line_errors(tmp_path: Path, lines: str, line: int,
                                               message: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(SCENARIO_HEAD + lines)
    with pytest.raises(InputError) as info:
        load_scenario(path)
    text = str(info.value)
    assert text.startswith(f"{path}:{line}: "), text
    assert message in text and "\n" not in text


def test_steered_crowd_reaches_its_waypoints() -> None:
    scenario = load_scenario(SCENARIOS_DIR / "steered_crowd.yaml")
    with build_simulation(scenario) as sim:
        gaits = set()
        # The runner slows to a walk for each of its three right-angle corners (to stay within
        # 0.25 m of its path): it arrives at 20.9 s, the walkers by 16 s, within the scenario.
        for _ in range(round(scenario.duration_s * scenario.fps)):
            sim.step()
            gaits |= set(sim.store.gait.tolist())
        assert gaits == {0, 1, 2}  # stands, walks and runs
        for k, c in enumerate(scenario.characters):
            assert c.steering is not None
            assert sim.arrived(int(sim.store.entity[k])), c.name
            end = np.array(c.steering.path_m[-1])
            assert np.linalg.norm(sim.store.positions[k, 0, :2] - end) < 0.3, c.name


def test_the_game_loop_example_runs_and_follows_the_point() -> None:
    repo = REPO
    done = subprocess.run([sys.executable, "examples/steer_to_point.py"], cwd=repo,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    out = done.stdout
    assert "gaits: idle -> run -> walk -> idle" in out, out
    following = re.search(r"4-16 s: median ([\d.]+) m, max ([\d.]+) m", out)
    assert following and float(following.group(2)) < 2.0, out
    end = re.search(r"([\d.]+) m from the point at the end, arrived: True", out)
    assert end and float(end.group(1)) < 0.3, out
    assert "max 0.000 mm a frame; sole below the ground: 0.000 mm" in out, out


def test_removing_a_steered_character_keeps_the_others_on_their_paths(
        motions: dict[str, NormalizedMotion]) -> None:
    sim, entities = walkers(motions, (1.20, 1.75, 2.00), Plane())
    goals = [(3.0, 0.0), (0.0, 3.0), (-3.0, 0.0)]
    for e, goal in zip(entities, goals, strict=True):
        sim.walk_to(e, goal)
    for _ in range(30):
        sim.step()
    sim.remove(entities[1])
    for _ in range(round(8 * sim.fps)):
        sim.step()
    for e, goal in ((entities[0], goals[0]), (entities[2], goals[2])):
        assert sim.arrived(e)
        assert np.linalg.norm(sim.posture(e).positions[0, :2] - goal) < 0.3
