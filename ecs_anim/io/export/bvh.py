"""A played motion written as BVH text: Y up, one frame per line, ZXY rotation channels (DESIGN §8)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.morphology import Morphology
from ecs_anim.core.normalized import DecodedPose
from ecs_anim.core.rotations import matrix_to_euler
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.bvh import BvhWriteJoint, format_bvh
from ecs_anim.io.export.skeleton import (
    EULER_ORDER,
    EXPORT_JOINTS,
    EXPORT_PARENTS,
    local_rotations,
    rest_offsets,
)
from ecs_anim.io.importing import YUP_TO_ZUP

F64 = NDArray[np.float64]


def bvh_from_rotations(morph: Morphology, pelvis_in_world: F64, local: F64, fps: float) -> str:
    """BVH text from the pelvis path (frames, 3) in world metres and the export skeleton's local
    rotations (frames, len(EXPORT_NAMES), 3, 3) as given by :func:`local_rotations`."""
    joint_offsets, end_offsets = rest_offsets(morph)
    joints = [
        BvhWriteJoint(j.name, int(EXPORT_PARENTS[k]), joint_offsets[k],
                      None if j.end_site is None else end_offsets[k])
        for k, j in enumerate(EXPORT_JOINTS)
    ]
    euler = matrix_to_euler(local, EULER_ORDER)
    return format_bvh(joints, pelvis_in_world @ YUP_TO_ZUP, euler, 1.0 / fps, EULER_ORDER)


def bvh_text(pose: DecodedPose, morph: Morphology, fps: float) -> str:
    """BVH text of decoded poses on ``morph`` (see module docstring)."""
    return bvh_from_rotations(morph, pose.positions[:, J["pelvis"]], local_rotations(pose), fps)
