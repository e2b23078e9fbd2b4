"""The solver's limb step, compiled, for one character: each limb's highest-priority goal met
analytically, its second by swivelling about the axis that keeps the first, then the foot /
hand orientation (paper §9, fig. 11).

Mirrors ``ecs_anim.solver.shell._Solve.limbs`` (and ``_limb_joints``) for one character's row
of the solve state, written in place: its pose row (``leg_frame``, ``leg_fraction``,
``foot_dir``, ``arm_frame``, ``arm_fraction``, ``hand_dir``) and decoded row (limb joints and
half-plane frames).
"""

from __future__ import annotations

import math

from ecs_anim.runtime.kernels.decode import (
    DecodedArrays,
    PoseArrays,
    distal_frames,
    two_bone_middle,
)
from ecs_anim.runtime.kernels.solve_math import (
    bone_coords,
    point_in_limb,
    reach_end,
    reach_end_applies,
    reach_point,
    turn_about_axis,
)
from ecs_anim.runtime.kernels.solve_points import (
    I64,
    Bodies,
    Goals,
    Tables,
    Winners,
    goal_point,
    plain_point,
)
from ecs_anim.runtime.kernels.vec import (
    F64,
    Frame,
    Vec3,
    add,
    dot,
    in_frame,
    jit,
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


@jit(inline="always")
def _store_limb(frames: F64, fractions: F64, directions: F64, c: int, slot: int, frame: Frame,
                fraction: float, direction: Vec3) -> None:
    """Write limb ``slot`` of its kind (legs or arms) of character ``c``: its half-plane frame
    into ``frames`` (``leg2world`` / ``arm2world``), its fraction and distal direction."""
    store_frame(frames[c, slot], frame)
    fractions[c, slot] = fraction
    store3(directions[c, slot], direction)


@jit(inline="always")
def limb_joints(positions: F64, c: int, li: int, frame: Frame, fraction: float,
                direction: Vec3, lengths_row: F64, limb_joint: I64, limb_length: I64) -> None:
    """Mirrors ``_Solve._limb_joints``: the middle, end and distal joints of limb ``li`` from
    its frame, length fraction and distal direction (``positions`` the decoded joints)."""
    u = lengths_row[limb_length[li, 0]]
    ll = lengths_row[limb_length[li, 1]]
    h = lengths_row[limb_length[li, 2]]
    mid, end = two_bone_middle(frame, load3(positions[c, limb_joint[li, 0]]), u, ll,
                               fraction * (u + ll))
    store_limb_joints(positions, c, li, limb_joint, mid, end, distal_frames(frame, mid, end),
                      direction, h)


@jit(inline="always")
def store_limb_joints(positions: F64, c: int, li: int, limb_joint: I64, mid: Vec3, end: Vec3,
                      lower2world: Frame, direction: Vec3, h: float) -> None:
    """Limb ``li``'s middle and end joints into row ``c`` of ``positions`` (m), and its distal
    joint ``h`` (m) from the end along ``direction`` (in the lower bone's frame
    ``lower2world``)."""
    store3(positions[c, limb_joint[li, 1]], mid)
    store3(positions[c, limb_joint[li, 2]], end)
    store3(positions[c, limb_joint[li, 3]], add(end, scale(to_world(lower2world, direction), h)))


@jit(inline="always")
def solve_limbs(c: int, pose: PoseArrays, dec: DecodedArrays, g: Goals, w: Winners,
                b: Bodies, t: Tables, tolerance_m: float, leg_extension: float) -> None:
    """Mirrors ``ecs_anim.solver.shell._Solve.limbs`` for character ``c`` (its rows of ``pose``
    and ``dec`` written in place). ``leg_extension``: the longest a leg stretches, as a share of
    thigh + shank (arms: 1)."""
    # The arrays are taken out of the state tuples once: passing a tuple on costs a reference
    # count per array it holds.
    lengths_row = b.lengths[c]
    positions = dec.positions
    limb_joint, limb_length = t.limb_joint, t.limb_length
    goal, offset = g.goal, g.offset
    for li in range(4):
        first = w.first_limb[c, li]
        orient = w.orient_limb[c, li]
        changed = False
        slot = li if li < 2 else li - 2
        frames = dec.leg2world if li < 2 else dec.arm2world
        fractions = pose.leg_fraction if li < 2 else pose.arm_fraction
        directions = pose.foot_dir if li < 2 else pose.hand_dir
        frame = load_frame(frames[c, slot])
        fraction = float(fractions[c, slot])
        direction = load3(directions[c, slot])
        if first >= 0:
            second = w.second_limb[c, li]
            plain = offset[first, 0] == 0.0 and offset[first, 1] == 0.0 and offset[first, 2] == 0.0
            if plain:
                now = plain_point(positions, c, t.seg_proximal[g.segment[first]],
                                  t.seg_distal[g.segment[first]], g.fraction[first])
            else:
                now = goal_point(dec, c, g, first, t)
            miss = sub(now, load3(goal[first]))
            met = math.sqrt(miss[0] ** 2 + miss[1] ** 2 + miss[2] ** 2) <= tolerance_m * 0.01
            if met and second >= 0:  # a limb left alone keeps both its goals as they are
                miss = sub(goal_point(dec, c, g, second, t), load3(goal[second]))
                met = math.sqrt(miss[0] ** 2 + miss[1] ** 2 + miss[2] ** 2) <= tolerance_m * 0.01
            if not met:
                changed = True
                u = lengths_row[limb_length[li, 0]]
                ll = lengths_row[limb_length[li, 1]]
                h = lengths_row[limb_length[li, 2]]
                root = load3(positions[c, limb_joint[li, 0]])
                extension = leg_extension if li < 2 else 1.0
                to_goal = sub(load3(goal[first]), root)
                distance = math.sqrt(dot(to_goal, to_goal))
                if (plain and g.bone[first] == 1 and g.fraction[first] == 1.0
                        and reach_end_applies(u, ll, distance, dot(frame[2], to_goal),
                                              extension)):
                    # The limb's end (an ankle, a wrist) onto its goal: reach_point's limb to
                    # rounding, without its trigonometry.
                    frame, fraction, point = reach_end(root, frame, u, ll, to_goal, distance,
                                                       extension)
                else:
                    q, on_lower = bone_coords(g.bone[first], g.fraction[first],
                                              load3(offset[first]), u, ll, h, direction)
                    frame, fraction, point = reach_point(root, frame, u, ll, fraction, on_lower,
                                                         q, load3(goal[first]), extension)
                if second >= 0:
                    q2, lower2 = bone_coords(g.bone[second], g.fraction[second],
                                             load3(offset[second]), u, ll, h, direction)
                    local2 = point_in_limb(u, ll, fraction, lower2, q2)
                    p2 = add(root, to_world(frame, local2))
                    frame = matmul(turn_about_axis(root, point, p2, load3(goal[second])), frame)
                # The joints from the new frame (limb_joints' arithmetic, its lower bone's frame
                # computed once where a held foot's direction needs it too).
                mid, end = two_bone_middle(frame, root, u, ll, fraction * (u + ll))
                lower2world = distal_frames(frame, mid, end)
                if g.table_index[first] < 0:
                    # A foot held where ground adaptation put it keeps its world direction.
                    direction = in_frame(lower2world, load3(b.foot_in_world[c, li]))
                _store_limb(frames, fractions, directions, c, slot, frame, fraction, direction)
                store_limb_joints(positions, c, li, limb_joint, mid, end, lower2world, direction,
                                  h)
        if orient >= 0:
            changed = True
            lower2world = distal_frames(frame, load3(positions[c, limb_joint[li, 1]]),
                                        load3(positions[c, limb_joint[li, 2]]))
            direction = normalize(in_frame(lower2world, load3(goal[orient])))
            _store_limb(frames, fractions, directions, c, slot, frame, fraction, direction)
            limb_joints(positions, c, li, frame, fraction, direction, lengths_row, limb_joint,
                        limb_length)
        if changed:
            if li < 2:
                parent = transpose(load_frame(dec.pelvis2world[c]))
                store4(pose.leg_frame[c, li], quat_from_matrix(matmul(parent, frame)))
            else:
                parent = transpose(load_frame(dec.thorax2world[c]))
                store4(pose.arm_frame[c, li - 2], quat_from_matrix(matmul(parent, frame)))
