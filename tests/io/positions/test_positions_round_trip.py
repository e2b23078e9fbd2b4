"""Issue 34, items 1 and 5: a BVH clip forward-kinematicised to each layout, imported as joint
positions and exported on its source body, returns the layout's joints within 1 mm on every
frame; its contacts start within one frame of the BVH import's where the layout has toes."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from conftest import MOCAP_DIR, require_mocap
from ecs_anim.io.contacts import true_runs
from ecs_anim.io.export import export_motion, play_on
from ecs_anim.io.export.positions import in_layout_axes, layout_positions
from ecs_anim.io.importing import import_bvh
from ecs_anim.io.position_layouts import LAYOUTS
from ecs_anim.io.positions import PositionOptions, import_positions

CLIPS = ("bandai_walk.bvh", "bandai_run.bvh", "varied/cmu_walk_120hz_adelaide.bvh",
         "cmumax_131_02_start_walk_stop_m.bvh")
#: Layouts with no toe joint: the toe is filled in flat ahead of the ankle and moves with it, so
#: the foot's pitch is not known and a touch-down, which BVH import finds by the heel point (the
#: ankle-to-toe line behind the ankle) coming down, is found on the ankle (within the heel's
#: 2.5 mm plus the ankle's typical 5 mm rise at heel strike, ``ANKLE_RISE_AT_STRIKE_M``).
#: Measured on the 21 dev BVH files (h36m / coco17): 516 / 512 of 758 touch-downs within one
#: frame of the BVH import's, every one on 7 files (437 / 433 and 4 files with 2.5 mm alone).
#: One frame everywhere is beyond the data: at the BVH's touch-downs the ankle stands 0-29 mm
#: (10-90 %) above its lowest in the stance, and a stance on the ball alone is not seen
#: (docs/import.md, "Contacts without toe joints"). Held to a frame on walks at 30 and 120 Hz:
TOELESS_HELD = ("bandai_walk.bvh", "varied/asf_noneck_walk_speeds_120hz.bvh")
TOELESS = ("h36m", "coco17")


def layout_file(clip: str, layout_name: str, tmp_path):
    """The clip's BVH import decoded on its own body, as the layout's joints in its axes and
    unit, written to a .npy (MediaPipe's kept in the world here, so its contacts can be
    compared: its own files put the hips at the origin)."""
    motion = import_bvh(MOCAP_DIR / clip)
    layout = dataclasses.replace(LAYOUTS[layout_name], hips_origin=False)
    pose = play_on(motion, motion.source_morphology, True)
    array = in_layout_axes(layout_positions(pose, motion.source_morphology.leg_length, layout),
                           layout)
    path = tmp_path / f"{layout_name}.npy"
    np.save(path, array)
    return motion, layout, array, path


def onsets(contacts):
    """Touch-down frames of each foot, [left, right]."""
    return [[a for a, _ in true_runs(contacts[:, side]) if a > 0] for side in range(2)]


def worst_onset_frames(a, b):
    """The farthest any touch-down of ``a`` lies from the nearest of ``b``'s, and back."""
    worst = 0
    for side in range(2):
        for mine, theirs in ((a[side], b[side]), (b[side], a[side])):
            for frame in mine:
                worst = max(worst, min((abs(frame - f) for f in theirs), default=10**6))
    return worst


@pytest.mark.parametrize("clip", CLIPS)
@pytest.mark.parametrize("layout_name", list(LAYOUTS))
def test_layout_round_trip_within_a_millimetre(clip, layout_name, tmp_path):
    require_mocap()
    source, layout, array, path = layout_file(clip, layout_name, tmp_path)
    motion = import_positions(path, PositionOptions(layout=layout_name, fps=source.fps))
    out = tmp_path / f"{layout_name}_back.npy"
    export_motion(motion, "source", out, layout=layout_name)
    back = np.load(out).astype(np.float64)
    if layout.name == "mediapipe33":  # the export puts the hips at the origin, as MediaPipe
        hips = [layout.index("left_hip"), layout.index("right_hip")]
        array = array - array[:, hips].mean(axis=1, keepdims=True)
    assert back.shape == array.shape
    error_mm = np.linalg.norm(back - array, axis=-1) * layout.export_unit_m * 1000
    assert error_mm.max() < 1.0, (clip, layout_name, float(error_mm.max()))
    if layout_name not in TOELESS:
        assert worst_onset_frames(onsets(source.contacts()), onsets(motion.contacts())) <= 1


@pytest.mark.parametrize("clip", TOELESS_HELD)
@pytest.mark.parametrize("layout_name", TOELESS)
def test_walks_without_toe_joints_touch_down_within_a_frame(clip, layout_name, tmp_path):
    require_mocap()
    source, _, _, path = layout_file(clip, layout_name, tmp_path)
    motion = import_positions(path, PositionOptions(layout=layout_name, fps=source.fps))
    assert worst_onset_frames(onsets(source.contacts()), onsets(motion.contacts())) <= 1


def test_every_layout_joint_is_placed_by_export():
    """Each layout joint is a canonical joint, a blend or a head offset (export's three rules),
    and every blend's weights sum to 1 (an affine blend: it moves and scales with the body)."""
    for layout in LAYOUTS.values():
        direct = {s[0] for s in layout.canonical.values() if len(s) == 1}
        for joint in layout.joints:
            assert joint in direct or joint in layout.blends or joint in layout.head_offsets, \
                (layout.name, joint)
        for joint, weights in layout.blends.items():
            assert abs(sum(weights.values()) - 1.0) < 1e-12, (layout.name, joint)
