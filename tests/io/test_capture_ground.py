"""Issue 31, item 2: the ground a capture stood on is estimated at import and taken out of the
motion, so an uneven-terrain capture plays with its feet and pelvis on the character's ground."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from conftest import MOCAP_DIR, require_mocap
from ecs_anim import Plane
from ecs_anim.apps.batch.jobs import import_clip
from ecs_anim.core.normalized import decode
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.bvh import read_bvh
from ecs_anim.io.importing import canonical_clip, normalize_clip
from ecs_anim.runtime.metrics import MetricsRecorder
from ecs_anim.scenario import build_simulation
from support.scenarios import clip_on_body


def _mocap(name: str):
    require_mocap()
    path = MOCAP_DIR / name
    if not path.is_file():
        pytest.skip(f"{path} not found")
    return path


def _heel_soles(motion) -> np.ndarray:
    """Planted heels' soles (m above the capture's ground) of a motion decoded on its own
    body."""
    body = motion.source_morphology
    positions = decode(motion.poses, body.lengths).positions
    positions[..., 2] -= motion.ground_under()[:, None] * body.leg_length
    heel = motion.planted_part("heel")
    soles = [positions[heel[:, side], J[f"ankle_{s}"], 2] - body[f"ankle_height_{s}"]
             for side, s in enumerate("lr")]
    return np.concatenate(soles)


def test_a_walk_captured_on_a_ramp_is_stored_on_level_ground():
    """The same walk, its every frame raised along a 1:10 ramp as it goes, is stored as the level
    walk: the ramp is found (its rise along the walk) and taken out, planted heels on it within
    2 cm (each stance stood on its own level of the ramp, 6 cm above the last: the ground under
    the body is the lowest supporting level, smoothed) and the root over it within 2 cm of the
    level walk's; the poses keep the ramp (decoded on the source body, the source comes back)."""
    clip = canonical_clip(read_bvh(_mocap("bandai_walk.bvh")))
    level = normalize_clip(clip, "level", "level")
    travel = clip.positions[:, J["pelvis"], 0] - clip.positions[0, J["pelvis"], 0]
    ramp = clip.positions.copy()
    ramp[..., 2] += 0.1 * travel[:, None]
    motion = normalize_clip(replace(clip, positions=ramp), "ramp", "ramp")
    ground = motion.info["capture_ground"]
    assert ground["from"] == "contacts"
    assert ground["highest_m"] - ground["lowest_m"] > 0.8 * 0.1 * abs(travel[-1])
    assert np.abs(_heel_soles(motion)).max() < 0.02
    root = motion.poses.root_position[:, 2] - motion.ground_under() \
        - (level.poses.root_position[:, 2] - level.ground_under())
    assert np.abs(root).max() * motion.source_morphology.leg_length < 0.02
    leg = motion.source_morphology.leg_length
    assert np.allclose(motion.poses.root_position[:, 2] * leg, ramp[:, J["pelvis"], 2])


def test_an_uneven_terrain_capture_walks_on_flat_ground():
    """CMU 03_01 walks down uneven terrain (its ankles end 12-18 cm under where it started): on
    flat ground its pelvis stays at one height as a walk's does (p5-p95 within 0.15 m on a
    1.75 m body; 0.30 m when the terrain was played as motion), its soles on the ground."""
    motion = import_clip(_mocap("varied/cmudaz_03_01_uneven_terrain.bvh"))
    ground = motion.info["capture_ground"]
    assert ground["from"].startswith("contacts")
    assert ground["lowest_m"] < -0.12
    scenario = clip_on_body(motion, 1.75, Plane())
    pelvis = []
    with build_simulation(scenario) as sim:
        recorder = MetricsRecorder(sim)
        for _ in range(round(scenario.duration_s * scenario.fps)):
            sim.step()
            recorder.record()
            pelvis.append(sim.store.positions[0, J["pelvis"], 2])
        report = recorder.report()["characters"][0]
    low, high = np.percentile(pelvis, [5, 95])
    assert high - low < 0.15, (low, high)
    assert report["floating_mm_max"] <= 1.0 and report["ground_penetration_mm_max"] <= 1.0


def test_contacts_that_jump_as_no_ground_does_leave_the_ground_level():
    """A video estimate drifting in depth (the MediaPipe dance: its contacts up to 0.86 m apart
    in height within a second) shows no ground: it is kept level, and import says why."""
    motion = import_clip(_mocap("varied2/mediapipe_16joints_notoes_dance_30fps.bvh"))
    ground = motion.info["capture_ground"]
    assert ground["from"].startswith("level:") and "off any walkable ground" in ground["from"]
    assert ground["lowest_m"] == ground["highest_m"]
