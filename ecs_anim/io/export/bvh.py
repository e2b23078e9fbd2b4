"""A played motion written as BVH text: Y up, one frame per line, ZXY rotation channels (DESIGN §8).

A body that changed while the motion played (``Simulation.set_body``; ``lengths`` given, not
every frame on ``morph``) is written exactly: the rest skeleton (OFFSETs) is ``morph``, the
final body, and every joint whose offset differs on some frame gets three position channels
(``Xposition Yposition Zposition`` before its rotations, as the root has) holding its offset
on each frame; end sites that change (toe tips, the top of the head, the hands) become joints
named as in the glTF export (``toe_tip_l``, ``head_top``, ``hand_l``, ...) with such channels
and a zero-length End Site. A body that never changed is written as before, byte for byte.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.morphology import Morphology
from ecs_anim.core.normalized import DecodedPose
from ecs_anim.core.rotations import matrix_to_euler
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.bvh import BvhWriteJoint, format_bvh
from ecs_anim.io.export.gltf import END_SITE_NAMES
from ecs_anim.io.export.skeleton import (
    EULER_ORDER,
    EXPORT_JOINTS,
    EXPORT_NAMES,
    EXPORT_PARENTS,
    changing_offsets,
    local_rotations,
    rest_offsets,
)
from ecs_anim.io.importing import YUP_TO_ZUP

F64 = NDArray[np.float64]


def bvh_from_rotations(morph: Morphology, pelvis_in_world: F64, local: F64, fps: float,
                       lengths: F64 | None = None) -> str:
    """BVH text from the pelvis path (frames, 3) in world metres and the export skeleton's local
    rotations (frames, len(EXPORT_NAMES), 3, 3) as given by :func:`local_rotations`.

    ``lengths`` (frames, N_LENGTHS) metres: the body each frame was posed on (``store.lengths``
    recorded per tick), when it changed; ``morph`` is then the rest skeleton (the final body)
    and the changing offsets are animated (see the module docstring). None: ``morph`` on every
    frame."""
    joint_offsets, end_offsets = rest_offsets(morph)
    joints = [
        BvhWriteJoint(j.name, int(EXPORT_PARENTS[k]), joint_offsets[k],
                      None if j.end_site is None else end_offsets[k])
        for k, j in enumerate(EXPORT_JOINTS)
    ]
    euler = matrix_to_euler(local, EULER_ORDER)
    root = pelvis_in_world @ YUP_TO_ZUP
    moving = changing_offsets(morph, lengths)
    if moving is None:
        return format_bvh(joints, root, euler, 1.0 / fps, EULER_ORDER)
    frame_joints, frame_ends, joint_moves, end_moves = moving
    # The changing end sites become joints right after their (childless) parents, so the
    # list stays in the hierarchy's depth-first order; the others' indices shift.
    order: list[tuple[int, bool]] = []  # (export joint, is its end-site joint)
    for k in range(len(EXPORT_JOINTS)):
        order += [(k, False)] + ([(k, True)] if end_moves[k] else [])
    at = {item: i for i, item in enumerate(order)}
    written, angles, translations = [], [], {}
    for i, (k, is_end) in enumerate(order):
        if is_end:
            written.append(BvhWriteJoint(END_SITE_NAMES[EXPORT_NAMES[k]], at[k, False],
                                         end_offsets[k], np.zeros(3)))
            angles.append(np.zeros_like(euler[:, k]))
            translations[i] = frame_ends[:, k]
            continue
        j = joints[k]
        written.append(BvhWriteJoint(j.name, -1 if j.parent < 0 else at[j.parent, False],
                                     j.offset, None if end_moves[k] else j.end_site))
        angles.append(euler[:, k])
        if joint_moves[k]:
            translations[i] = frame_joints[:, k]
    return format_bvh(written, root, np.stack(angles, axis=1), 1.0 / fps, EULER_ORDER,
                      translations=translations)


def bvh_text(pose: DecodedPose, morph: Morphology, fps: float) -> str:
    """BVH text of decoded poses on ``morph`` (see module docstring)."""
    return bvh_from_rotations(morph, pose.positions[:, J["pelvis"]], local_rotations(pose), fps)
