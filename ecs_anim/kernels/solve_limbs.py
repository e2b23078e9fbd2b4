"""The solver's limb step, compiled, for one character: each limb's highest-priority goal met
analytically, its second by swivelling about the axis that keeps the first, then the foot /
hand orientation (paper §9, fig. 11).

Mirrors ``ecs_anim.solver_shell._Solve.limbs`` (and ``_limb_joints``) for one character's row
of the solve state, written in place: its pose row (``leg_frame``, ``leg_fraction``,
``foot_dir``, ``arm_frame``, ``arm_fraction``, ``hand_dir``) and decoded row (limb joints and
half-plane frames).
"""

from __future__ import annotations

import math

from numba import njit

from .decode import DecodedArrays, PoseArrays, distal_frames, two_bone_middle
from .solve_math import bone_coords, point_in_limb, reach_point, turn_about_axis
from .solve_points import Bodies, Goals, Tables, Winners, goal_point, limb_frame
from .vec import (
    F64,
    Frame,
    Vec3,
    add,
    in_frame,
    load3,
    load_frame,
    matmul,
    normalize,
    quat_from_matrix,
    scale,
    store3,
    store4,
    store_frame,
    sub,
    to_world,
    transpose,
)


@njit(cache=True, inline="always")
def limb_fraction(pose: PoseArrays, c: int, li: int) -> float:
    return float(pose.leg_fraction[c, li] if li < 2 else pose.arm_fraction[c, li - 2])


@njit(cache=True, inline="always")
def limb_dir(pose: PoseArrays, c: int, li: int) -> Vec3:
    """The foot / hand direction of limb ``li`` in its lower bone's frame."""
    return load3(pose.foot_dir[c, li]) if li < 2 else load3(pose.hand_dir[c, li - 2])


@njit(cache=True, inline="always")
def _store_limb(pose: PoseArrays, dec: DecodedArrays, c: int, li: int, frame: Frame,
                fraction: float, direction: Vec3) -> None:
    if li < 2:
        store_frame(dec.leg2world[c, li], frame)
        pose.leg_fraction[c, li] = fraction
        store3(pose.foot_dir[c, li], direction)
    else:
        store_frame(dec.arm2world[c, li - 2], frame)
        pose.arm_fraction[c, li - 2] = fraction
        store3(pose.hand_dir[c, li - 2], direction)


@njit(cache=True, inline="always")
def limb_joints(dec: DecodedArrays, c: int, li: int, frame: Frame, fraction: float,
                direction: Vec3, lengths_row: F64, t: Tables) -> None:
    """Mirrors ``_Solve._limb_joints``: the middle, end and distal joints of limb ``li`` from
    its frame, length fraction and distal direction."""
    u = lengths_row[t.limb_length[li, 0]]
    ll = lengths_row[t.limb_length[li, 1]]
    h = lengths_row[t.limb_length[li, 2]]
    p = dec.positions[c]
    mid, end = two_bone_middle(frame, load3(p[t.limb_joint[li, 0]]), u, ll, fraction * (u + ll))
    lower2world = distal_frames(frame, mid, end)
    store3(p[t.limb_joint[li, 1]], mid)
    store3(p[t.limb_joint[li, 2]], end)
    store3(p[t.limb_joint[li, 3]], add(end, scale(to_world(lower2world, direction), h)))


@njit(cache=True, inline="always")
def solve_limbs(c: int, pose: PoseArrays, dec: DecodedArrays, g: Goals, w: Winners,
                b: Bodies, t: Tables, tolerance_m: float, leg_extension: float) -> None:
    """Mirrors ``ecs_anim.solver_shell._Solve.limbs`` for character ``c`` (its rows of ``pose``
    and ``dec`` written in place). ``leg_extension``: the longest a leg stretches, as a share of
    thigh + shank (arms: 1)."""
    lengths_row = b.lengths[c]
    for li in range(4):
        first = w.first_limb[c, li]
        orient = w.orient_limb[c, li]
        changed = False
        frame = limb_frame(dec, c, li)
        fraction = limb_fraction(pose, c, li)
        direction = limb_dir(pose, c, li)
        if first >= 0:
            second = w.second_limb[c, li]
            miss = sub(goal_point(dec, c, g, first, t), load3(g.goal[first]))
            met = math.sqrt(miss[0] ** 2 + miss[1] ** 2 + miss[2] ** 2) <= tolerance_m * 0.01
            if not met or second >= 0:
                changed = True
                u = lengths_row[t.limb_length[li, 0]]
                ll = lengths_row[t.limb_length[li, 1]]
                h = lengths_row[t.limb_length[li, 2]]
                root = load3(dec.positions[c, t.limb_joint[li, 0]])
                q, on_lower = bone_coords(g.bone[first], g.fraction[first], load3(g.offset[first]),
                                          u, ll, h, direction)
                extension = leg_extension if li < 2 else 1.0
                frame, fraction, point = reach_point(root, frame, u, ll, fraction, on_lower, q,
                                                     load3(g.goal[first]), extension)
                if second >= 0:
                    q2, lower2 = bone_coords(g.bone[second], g.fraction[second],
                                             load3(g.offset[second]), u, ll, h, direction)
                    local2 = point_in_limb(u, ll, fraction, lower2, q2)
                    p2 = add(root, to_world(frame, local2))
                    frame = matmul(turn_about_axis(root, point, p2, load3(g.goal[second])), frame)
                if g.table_index[first] < 0:
                    # A foot held where ground adaptation put it keeps its world direction.
                    mid, end = two_bone_middle(frame, root, u, ll, fraction * (u + ll))
                    lower2world = distal_frames(frame, mid, end)
                    direction = in_frame(lower2world, load3(b.foot_in_world[c, li]))
                _store_limb(pose, dec, c, li, frame, fraction, direction)
                limb_joints(dec, c, li, frame, fraction, direction, lengths_row, t)
        if orient >= 0:
            changed = True
            p = dec.positions[c]
            lower2world = distal_frames(frame, load3(p[t.limb_joint[li, 1]]),
                                        load3(p[t.limb_joint[li, 2]]))
            direction = normalize(in_frame(lower2world, load3(g.goal[orient])))
            _store_limb(pose, dec, c, li, frame, fraction, direction)
            limb_joints(dec, c, li, frame, fraction, direction, lengths_row, t)
        if changed:
            if li < 2:
                parent = transpose(load_frame(dec.pelvis2world[c]))
                store4(pose.leg_frame[c, li], quat_from_matrix(matmul(parent, frame)))
            else:
                parent = transpose(load_frame(dec.thorax2world[c]))
                store4(pose.arm_frame[c, li - 2], quat_from_matrix(matmul(parent, frame)))

