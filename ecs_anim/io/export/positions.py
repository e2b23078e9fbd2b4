"""Joint positions in a research layout (``export -o X.npy --layout humanml3d``): a played
motion's joints in the layout's order, axes and unit, for training pipelines
(:mod:`ecs_anim.io.position_layouts`)."""

from __future__ import annotations

from typing import IO

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.normalized import DecodedPose
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.importing import UP_AXES
from ecs_anim.io.position_layouts import PositionLayout

F64 = NDArray[np.float64]


def layout_positions(pose: DecodedPose, leg_m: float, layout: PositionLayout) -> F64:
    """The layout's joints (n_frames, n_layout_joints, 3), metres, world Z up, from a decoded
    pose: each the canonical joint it is, or placed as the layout's table says (a blend of
    canonical joints, an offset in the head's frame scaled by ``leg_m``, thigh + shank m).
    A joint read as the middle of two (COCO's ears: the head) is placed by its own rule."""
    p = pose.positions
    out = np.empty((len(p), len(layout.joints), 3))
    direct = {sources[0]: joint for joint, sources in layout.canonical.items() if len(sources) == 1}
    for k, name in enumerate(layout.joints):
        if name in layout.blends:
            out[:, k] = sum(w * p[:, J[joint]] for joint, w in layout.blends[name].items())
        elif name in layout.head_offsets:
            offset = np.array(layout.head_offsets[name]) * leg_m
            out[:, k] = p[:, J["head"]] + pose.head2world @ offset
        else:
            out[:, k] = p[:, J[direct[name]]]
    return out


def in_layout_axes(positions: F64, layout: PositionLayout) -> F64:
    """World positions (n_frames, n_joints, 3), metres Z up, in the layout's own axes and unit
    (``export_up``, ``export_unit_m``), the hips' middle at the origin where the layout has it
    so (MediaPipe's world landmarks)."""
    if layout.hips_origin:
        hips = [layout.index(f"{side}_hip") for side in ("left", "right")]
        positions = positions - positions[:, hips].mean(axis=1, keepdims=True)
    in_file: F64 = positions @ UP_AXES[layout.export_up] / layout.export_unit_m
    return in_file


def write_layout_positions(f: IO[bytes], positions: F64, layout: PositionLayout, fps: float,
                           npz: bool) -> None:
    """Write layout positions (n_frames, n_joints, 3) in the layout's axes and unit
    (:func:`in_layout_axes`) to the binary file ``f``: a ``.npy`` array of float32, as the
    datasets ship theirs, or (``npz``) an archive with ``positions``, ``joint_names``, ``fps``,
    ``layout``, ``up`` and ``unit_m``, which import reads back with no flag."""
    array = in_layout_axes(positions, layout).astype(np.float32)
    if not npz:
        np.save(f, array)
        return
    np.savez_compressed(f, positions=array, joint_names=np.array(layout.joints),
                        fps=np.float64(fps), layout=np.array(layout.name),
                        up=np.array(layout.export_up), unit_m=np.float64(layout.export_unit_m))
