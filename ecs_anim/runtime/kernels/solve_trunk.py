"""The solver's trunk step, compiled, for one character: one CCD turn about the spine's base
for the highest-priority goal the trunk can still improve, spread along the spine.

Mirrors ``ecs_anim.solver.shell._Solve.trunk`` for one character's row of the solve state,
written in place: pose ``spine_points`` and ``thorax``, then the row decoded again (a bent
spine's joints are exact once decoded), on which the higher-priority goals are checked.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ecs_anim.runtime.kernels.decode import DecodedArrays, PoseArrays, decode_row
from ecs_anim.runtime.kernels.solve_math import bring_within_reach
from ecs_anim.runtime.kernels.solve_points import (
    Goals,
    Tables,
    Winners,
    goal_point,
    segment_frame,
)
from ecs_anim.runtime.kernels.vec import (
    F64,
    axis_angle,
    axis_angle_of,
    jit,
    load3,
    load4,
    load_frame,
    matmul,
    matrix_from_quat,
    norm,
    quat_from_matrix,
    rotation_toward,
    store3,
    store4,
    sub,
    to_world,
    transpose,
)

#: Groups (ecs_anim.core.body_points.GROUPS) whose points the trunk carries: head, arms, trunk.
_HEAD, _TRUNK = 2, 5
#: The share of a carried limb's length the trunk aims to bring a goal within.
_LIMB_REACH_SHARE = 0.99


@jit(inline="always")
def solve_trunk(c: int, pose: PoseArrays, dec: DecodedArrays, lengths_row: F64, g: Goals,
                w: Winners, err: F64, stalled: NDArray[np.bool_], t: Tables, tolerance_m: float,
                tolerance_rad: float, max_ccd_step_rad: float) -> bool:
    """Mirrors ``ecs_anim.solver.shell._Solve.trunk`` for character ``c`` (in place) on its body
    ``lengths_row`` (N_LENGTHS,) (m); ``w`` the goals each limb and the head meet;
    ``err`` (k,) each goal's error now
    (:func:`~ecs_anim.runtime.kernels.solve_points.goal_error`), ``stalled``
    (k,) goals that stopped improving. Returns whether the trunk turned."""
    start, stop = g.start[c], g.start[c + 1]
    best = -1
    for j in range(start, stop):
        carried = g.group[j] >= _HEAD
        uses_trunk = (g.chain[j] & (1 << _TRUNK)) > 0
        tol = tolerance_rad if g.orientation[j] else tolerance_m
        # Highest priority; ties to the goal added last.
        if (uses_trunk and carried and err[j] > tol and not stalled[j]
                and (best < 0 or g.priority[j] >= g.priority[best])):
            best = j
    if best < 0:
        return False
    p = dec.positions[c]
    base = load3(p[t.pelvis])
    point = goal_point(dec, c, g, best, t)
    goal = load3(g.goal[best])
    turn = rotation_toward(sub(point, base), sub(goal, base), max_ccd_step_rad, 1.0)
    group = g.group[best]
    limb_root = t.group_limb_root[group]
    if g.orientation[best]:
        axis = to_world(segment_frame(dec, c, g.segment[best], t), load3(g.axis[best]))
        turn = rotation_toward(axis, goal, max_ccd_step_rad, 1.0)
    elif limb_root >= 0:
        # A head or arm point its limb cannot reach from where the limb's root is: bring that
        # root within reach rather than the point onto the goal.
        root_at = load3(p[limb_root])
        middle_at = load3(p[t.group_limb_middle[group]])
        if g.bone[best] == 0:
            reach = norm(sub(point, root_at))
        else:
            reach = _LIMB_REACH_SHARE * (norm(sub(middle_at, root_at))
                                         + norm(sub(point, middle_at)))
        if norm(sub(goal, root_at)) > reach:
            turn = bring_within_reach(base, root_at, goal, reach, max_ccd_step_rad)
    # Spread the turn along the spine (a third, two thirds, all of it at the neck); the thorax,
    # and all it carries, turns by all of it.
    spine_before = (load3(pose.spine_points[c, 0]), load3(pose.spine_points[c, 1]),
                    load3(pose.spine_points[c, 2]))
    thorax_before = load4(pose.thorax[c])
    pelvis2world = load_frame(dec.pelvis2world[c])
    turn_in_pelvis = matmul(matmul(transpose(pelvis2world), turn), pelvis2world)
    axis, angle = axis_angle_of(turn_in_pelvis)
    for k in range(3):
        part = axis_angle(axis, angle * (k + 1) / 3.0)
        store3(pose.spine_points[c, k], to_world(part, spine_before[k]))
    store4(pose.thorax[c],
           quat_from_matrix(matmul(turn_in_pelvis, matrix_from_quat(thorax_before))))
    decode_row(c, pose, lengths_row, dec)
    # A move that worsens any higher-priority goal the trunk carries is undone, measured on the
    # decoded result (the bent spine does not carry the neck where a rigid turn would).
    for j in range(start, stop):
        if g.group[j] >= _HEAD and not g.orientation[j] and g.priority[j] > g.priority[best]:
            point = goal_point(dec, c, g, j, t)
            goal = load3(g.goal[j])
            slot = t.limb_of_group[g.group[j]]
            if (w.first_limb[c, slot] == j) if slot >= 0 else (
                    g.group[j] == _HEAD and w.first_head[c] == j):
                # Met first by its limb (or the neck and head) on the next pass wherever the
                # turn carried it: what counts is how far it is beyond the limb's reach.
                root_at = load3(p[t.group_limb_root[g.group[j]]])
                if g.bone[j] == 0:
                    reach = norm(sub(point, root_at))
                else:
                    middle_at = load3(p[t.group_limb_middle[g.group[j]]])
                    reach = norm(sub(middle_at, root_at)) + norm(sub(point, middle_at))
                after = max(norm(sub(goal, root_at)) - reach, 0.0)
            else:
                after = norm(sub(point, goal))
            if after > err[j] + tolerance_m:
                for k in range(3):
                    store3(pose.spine_points[c, k], spine_before[k])
                store4(pose.thorax[c], thorax_before)
                decode_row(c, pose, lengths_row, dec)
                return False
    return True

