"""The solver's limb step, compiled, for one character: each limb's highest-priority goal met
analytically, its second by swivelling about the axis that keeps the first, then the foot /
hand orientation (paper §9, fig. 11).

Mirrors ``ecs_anim.solver.shell._Solve.limbs`` (and ``_limb_joints``) for one character's row
of the solve state, written in place: its pose row (``leg_frame``, ``leg_fraction``,
``foot_dir``, ``arm_frame``, ``arm_fraction``, ``hand_dir``) and decoded row (limb joints and
half-plane frames). The first pass's arm whose wrist goes onto its goal by
:func:`.solve_math.reach_end` is computed over the columns of a block's scratch, one a
character (:mod:`.lanes`' layout): :func:`.solve.solve_rows` gathers a block's arms and solves
them together on the vector units (:func:`arm_lanes`).
"""

from __future__ import annotations

import math

import numpy as np

from ecs_anim.runtime.kernels.decode import (
    DecodedArrays,
    PoseArrays,
    distal_frames,
    two_bone_middle,
)
from ecs_anim.runtime.kernels.lanes import (
    BLOCK,
    Column,
    at,
    col3,
    col_frame,
    distal_frames_lanes,
    pick3,
    put3,
    put4,
    put_frame,
    quat_from_matrix_lanes,
)
from ecs_anim.runtime.kernels.solve_math import (
    bone_coords,
    point_in_limb,
    point_in_limb_lanes,
    reach_end,
    reach_end_applies,
    reach_point,
    turn_about_axis,
    turn_about_axis_lanes,
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
                b: Bodies, t: Tables, tolerance_m: float, leg_extension: float,
                arm_block: F64, column: Column, may_wait: bool) -> bool:
    """Mirrors ``ecs_anim.solver.shell._Solve.limbs`` for character ``c`` (its rows of ``pose``
    and ``dec`` written in place). ``leg_extension``: the longest a leg stretches, as a share of
    thigh + shank (arms: 1). With ``may_wait``, the first arm whose wrist goes onto its first goal
    by :func:`.solve_math.reach_end` (a user goal; no orientation goal, no second goal on the
    hand) is only
    gathered into column ``column`` of ``arm_block`` (an :func:`arm_scratch` block), and True
    returned: the caller computes it with its block's (:func:`arm_lanes`), then
    :func:`scatter_arm` (each limb reads and writes only its own joints, so the arm may be
    solved after the other limbs)."""
    # The arrays are taken out of the state tuples once: passing a tuple on costs a reference
    # count per array it holds.
    lengths_row = b.lengths[c]
    positions = dec.positions
    limb_joint, limb_length = t.limb_joint, t.limb_length
    goal, offset = g.goal, g.offset
    waits = False
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
                u = lengths_row[limb_length[li, 0]]
                ll = lengths_row[limb_length[li, 1]]
                h = lengths_row[limb_length[li, 2]]
                root = load3(positions[c, limb_joint[li, 0]])
                extension = leg_extension if li < 2 else 1.0
                to_goal = sub(load3(goal[first]), root)
                distance = math.sqrt(dot(to_goal, to_goal))
                # The limb's end (an ankle, a wrist) onto its goal: reach_point's limb to
                # rounding, without its trigonometry.
                ends = (plain and g.bone[first] == 1 and g.fraction[first] == 1.0
                        and reach_end_applies(u, ll, distance, dot(frame[2], to_goal), extension))
                if (ends and may_wait and not waits and li >= 2 and orient < 0
                        and g.table_index[first] >= 0 and (second < 0 or g.bone[second] < 2)):
                    gather_arm(c, dec, g, li, second, root, frame, u, ll, h, to_goal, distance,
                               direction, arm_block, column)
                    waits = True
                else:
                    changed = True
                    if ends:
                        frame, fraction, point = reach_end(root, frame, u, ll, to_goal, distance,
                                                           extension)
                    else:
                        q, on_lower = bone_coords(g.bone[first], g.fraction[first],
                                                  load3(offset[first]), u, ll, h, direction)
                        frame, fraction, point = reach_point(root, frame, u, ll, fraction,
                                                             on_lower, q, load3(goal[first]),
                                                             extension)
                    if second >= 0:
                        q2, lower2 = bone_coords(g.bone[second], g.fraction[second],
                                                 load3(offset[second]), u, ll, h, direction)
                        local2 = point_in_limb(u, ll, fraction, lower2, q2)
                        p2 = add(root, to_world(frame, local2))
                        frame = matmul(turn_about_axis(root, point, p2, load3(goal[second])),
                                       frame)
                    # The joints from the new frame (limb_joints' arithmetic, its lower bone's
                    # frame computed once where a held foot's direction needs it too).
                    mid, end = two_bone_middle(frame, root, u, ll, fraction * (u + ll))
                    lower2world = distal_frames(frame, mid, end)
                    if g.table_index[first] < 0:
                        # A foot held where ground adaptation put it keeps its world direction.
                        direction = in_frame(lower2world, load3(b.foot_in_world[c, li]))
                    _store_limb(frames, fractions, directions, c, slot, frame, fraction,
                                direction)
                    store_limb_joints(positions, c, li, limb_joint, mid, end, lower2world,
                                      direction, h)
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
    return waits


# The arms' block scratch (:mod:`.lanes`' layout: rows of BLOCK values, a column a character).
# What arm_lanes reads: the shoulder, the arm's frame, its upper, lower and hand lengths, the
# way from the shoulder to the first goal and its length, 1.0 where there is a second goal,
# its point's coordinates in its bone and 1.0 where that is the lower bone, the second goal,
# the hand's direction and the thorax's frame; which arm (0 left, 1 right); ...
_A_ROOT, _A_FRAME, _A_UPPER, _A_LOWER, _A_HAND = 0, 3, 12, 13, 14
_A_TO_GOAL, _A_DISTANCE, _A_SECOND, _A_Q2, _A_ON_LOWER, _A_GOAL2 = 15, 18, 19, 20, 23, 24
_A_DIRECTION, _A_THORAX, _A_SLOT = 27, 30, 39
# ... what it writes (the arm's new frame over the old one): its fraction, elbow, wrist and
# hand joints, its frame's quaternion in the thorax's; and 1.0 where a character waits for it.
_A_FRACTION, _A_MIDDLE, _A_END, _A_DISTAL, _A_QUAT = 40, 41, 44, 47, 50
A_WAITING = 54
#: Rows of a block's arm scratch (:func:`arm_scratch`).
ARM_SCRATCH_ROWS = 55


def arm_scratch(n: int) -> F64:
    """The arms' scratch :func:`solve_limbs` needs for ``n`` rows: (n // BLOCK + 1, a block's
    ARM_SCRATCH_ROWS rows of BLOCK, flat), not zeroed: the chunk of rows from ``lo`` uses the
    block scratch ``lo // BLOCK`` alone, and :func:`.solve.solve_rows` zeroes it."""
    return np.empty((n // BLOCK + 1, ARM_SCRATCH_ROWS * BLOCK))


@jit(inline="always")
def gather_arm(c: int, dec: DecodedArrays, g: Goals, li: int, second: int, root: Vec3,
               frame: Frame, upper: float, lower: float, hand: float, to_goal: Vec3,
               distance: float, direction: Vec3, scratch: F64, j: Column) -> None:
    """What :func:`arm_lanes` needs of character ``c``'s arm ``li`` into column ``j`` of
    ``scratch``: its shoulder ``root``, ``frame``, bones' lengths, the way ``to_goal`` (m) to
    its first goal, ``distance`` (m) away, its second goal (-1: none; not on the hand) and
    its hand's ``direction``."""
    put3(scratch, _A_ROOT, j, root)
    put_frame(scratch, _A_FRAME, j, frame)
    scratch[at(_A_UPPER, j)], scratch[at(_A_LOWER, j)], scratch[at(_A_HAND, j)] = (upper, lower,
                                                                                   hand)
    put3(scratch, _A_TO_GOAL, j, to_goal)
    scratch[at(_A_DISTANCE, j)] = distance
    scratch[at(_A_SECOND, j)] = 1.0 if second >= 0 else 0.0
    if second >= 0:
        q2, on_lower = bone_coords(g.bone[second], g.fraction[second], load3(g.offset[second]),
                                   upper, lower, hand, direction)
        put3(scratch, _A_Q2, j, q2)
        scratch[at(_A_ON_LOWER, j)] = 1.0 if on_lower else 0.0
        put3(scratch, _A_GOAL2, j, load3(g.goal[second]))
    put3(scratch, _A_DIRECTION, j, direction)
    put_frame(scratch, _A_THORAX, j, load_frame(dec.thorax2world[c]))
    scratch[at(_A_SLOT, j)] = li - 2


# A call (one compiled body for a block's loop), not inlined.
@jit()
def arm_lanes(scratch: F64, start: Column, stop: Column) -> None:
    """The arm of each column ``start:stop`` of an arm scratch (:func:`gather_arm`) solved as
    :func:`solve_limbs` solves it (its wrist onto the first goal by
    :func:`.solve_math.reach_end`, swivelled toward the second goal, its joints and its
    frame's quaternion), in a loop over them that runs on the vector units: every case
    computed and the one that applies chosen (selects, no branch), with the scalar step's
    operations in its order, so the same bits in a lane or alone."""
    for k in range(start, stop):
        j = Column(k)  # (the same type: for mypy, which takes k for an int)
        root = col3(scratch, _A_ROOT, j)
        u, ll, h = scratch[at(_A_UPPER, j)], scratch[at(_A_LOWER, j)], scratch[at(_A_HAND, j)]
        frame, fraction, point = reach_end(root, col_frame(scratch, _A_FRAME, j), u, ll,
                                           col3(scratch, _A_TO_GOAL, j),
                                           scratch[at(_A_DISTANCE, j)], 1.0)
        local2 = point_in_limb_lanes(u, ll, fraction, scratch[at(_A_ON_LOWER, j)] != 0.0,
                                     col3(scratch, _A_Q2, j))
        p2 = add(root, to_world(frame, local2))
        turned = matmul(turn_about_axis_lanes(root, point, p2, col3(scratch, _A_GOAL2, j)),
                        frame)
        second = scratch[at(_A_SECOND, j)] != 0.0
        frame = (pick3(second, turned[0], frame[0]), pick3(second, turned[1], frame[1]),
                 pick3(second, turned[2], frame[2]))
        mid, end = two_bone_middle(frame, root, u, ll, fraction * (u + ll))
        lower2world = distal_frames_lanes(frame, mid, end)
        distal = add(end, scale(to_world(lower2world, col3(scratch, _A_DIRECTION, j)), h))
        parent = transpose(col_frame(scratch, _A_THORAX, j))
        put_frame(scratch, _A_FRAME, j, frame)
        scratch[at(_A_FRACTION, j)] = fraction
        put3(scratch, _A_MIDDLE, j, mid)
        put3(scratch, _A_END, j, end)
        put3(scratch, _A_DISTAL, j, distal)
        put4(scratch, _A_QUAT, j, quat_from_matrix_lanes(matmul(parent, frame)))


@jit(inline="always")
def scatter_arm(c: int, pose: PoseArrays, dec: DecodedArrays, t: Tables, scratch: F64,
                j: Column) -> None:
    """Write the arm :func:`arm_lanes` solved in column ``j`` into character ``c``'s rows:
    its frame, fraction, quaternion and joints (its hand's direction is unchanged)."""
    slot = int(scratch[at(_A_SLOT, j)])
    li = slot + 2
    store_frame(dec.arm2world[c, slot], col_frame(scratch, _A_FRAME, j))
    pose.arm_fraction[c, slot] = scratch[at(_A_FRACTION, j)]
    store4(pose.arm_frame[c, slot], (scratch[at(_A_QUAT, j)], scratch[at(_A_QUAT + 1, j)],
                                     scratch[at(_A_QUAT + 2, j)], scratch[at(_A_QUAT + 3, j)]))
    positions = dec.positions
    store3(positions[c, t.limb_joint[li, 1]], col3(scratch, _A_MIDDLE, j))
    store3(positions[c, t.limb_joint[li, 2]], col3(scratch, _A_END, j))
    store3(positions[c, t.limb_joint[li, 3]], col3(scratch, _A_DISTAL, j))
