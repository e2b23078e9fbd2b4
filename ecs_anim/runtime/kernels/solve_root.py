"""The solver's root step (``adaptRoot``), compiled: the root moves horizontally by the step
that brings the centre of mass back once the next pass has re-planted the legs (predicted), and
down where a planted leg could no longer reach its footprint (paper §9).

Mirrors ``ecs_anim.solver.shell._Solve.root`` for one character's row of the solve state,
written in place: pose ``root_position`` and every decoded joint (the legs re-aim next). The
step's arithmetic (:func:`root_lanes`) runs over the columns of a block's scratch, one a
character (:mod:`.lanes`' layout): :func:`.solve.solve_rows` gathers the first steps of a
block's characters and computes them together on the vector units, a later step alone.
"""

from __future__ import annotations

import math

import numpy as np

from ecs_anim.runtime.kernels.decode import DecodedArrays, PoseArrays, leg_length
from ecs_anim.runtime.kernels.lanes import BLOCK, Column, at, col3, put3
from ecs_anim.runtime.kernels.solve_points import (
    B8,
    I64,
    Bodies,
    Goals,
    Tables,
    Winners,
)
from ecs_anim.runtime.kernels.vec import (
    F64,
    Frame,
    Vec3,
    add,
    add_scaled,
    cross,
    dot,
    jit,
    load3,
    load_frame,
    scale,
    sub,
)

#: Mirrors ``ecs_anim.solver.shell.ROOT_PROBE_M`` and ``MIN_ROOT_JACOBIAN``.
ROOT_PROBE_M = 1e-3
MIN_ROOT_JACOBIAN = 0.1


@jit(inline="always")
def com_shortfall(c: int, positions: F64, masses: F64, com_fraction: F64, com_desired: F64,
                  com_on: B8, mass_proximal: I64, mass_distal: I64) -> tuple[float, float]:
    """The horizontal way (x, y) from character ``c``'s centre of mass to its desired place
    (m; 0 without COM control). Mirrors ``ecs_anim.solver.shell._Solve.com_shortfall``."""
    if not com_on[c]:
        return 0.0, 0.0
    # Mirrors solve_points.centre_of_mass (the same operations).
    total = 0.0
    x = y = 0.0
    for s in range(masses.shape[1]):
        a = load3(positions[c, mass_proximal[s]])
        bb = load3(positions[c, mass_distal[s]])
        seg_com = add_scaled(a, sub(bb, a), com_fraction[c, s])
        x += masses[c, s] * seg_com[0]
        y += masses[c, s] * seg_com[1]
        total += masses[c, s]
    return com_desired[c, 0] - x / total, com_desired[c, 1] - y / total


@jit(inline="always")
def middle_after_root_move(root: Vec3, end: Vec3, frame: Frame, upper: float, lower: float,
                           move: Vec3) -> Vec3:
    """Mirrors :func:`ecs_anim.solver.steps.middle_after_root_move` for one limb."""
    moved = add(root, move)
    to_end = sub(end, moved)
    span = math.sqrt(dot(to_end, to_end))
    z_new = scale(to_end, 1.0 / span)
    # Mirrors ecs_anim.core.normalized.two_sphere_middle.
    z_middle = (upper**2 - lower**2 + span**2) / (2.0 * max(span, 1e-12))
    y_middle = math.sqrt(max(upper**2 - z_middle**2, 0.0))
    z_now, y_now = frame[2], frame[1]
    axis = cross(z_now, z_new)
    cos = dot(z_now, z_new)
    along = dot(axis, y_now) / (1.0 + cos)
    turned = cross(axis, y_now)
    y_new = (y_now[0] * cos + turned[0] + axis[0] * along,
             y_now[1] * cos + turned[1] + axis[1] * along,
             y_now[2] * cos + turned[2] + axis[2] * along)
    return add(add(moved, scale(y_new, y_middle)), scale(z_new, z_middle))


@jit(inline="always")
def held_legs(c: int, positions: F64, g: Goals, w: Winners, t: Tables, tolerance_m: float) -> int:
    """Bit ``side`` set for each leg whose ankle the next pass keeps where it is: its goal a
    world point at the ankle (a planted foot's), met now, and no second goal. Mirrors
    ``_Solve.held_legs``."""
    held = 0
    for side in range(2):
        j = w.first_limb[c, side]
        if (j < 0 or w.second_limb[c, side] >= 0 or g.orientation[j] or g.on_self[j]
                or g.bone[j] != 1 or g.fraction[j] != 1.0 or g.offset[j, 0] != 0.0
                or g.offset[j, 1] != 0.0 or g.offset[j, 2] != 0.0):
            continue
        off = sub(load3(positions[c, t.ankle[side]]), load3(g.goal[j]))
        if math.sqrt(dot(off, off)) <= tolerance_m * 0.01:
            held |= 1 << side
    return held


@jit(inline="always")
def leg_shares(c: int, b: Bodies, t: Tables, li: int, total: float) -> tuple[float, float]:
    """The shares of character ``c``'s mass (``total`` kg) that move with leg ``li``'s knee
    and that stay with its ankle (mirrors ``_Solve.root_move``)."""
    upper, lower, distal = t.limb_mass[li, 0], t.limb_mass[li, 1], t.limb_mass[li, 2]
    upper_m, lower_m = b.masses[c, upper] / total, b.masses[c, lower] / total
    lower_f = b.com_fraction[c, lower]
    return (upper_m * b.com_fraction[c, upper] + lower_m * (1.0 - lower_f),
            lower_m * lower_f + b.masses[c, distal] / total)


# The root step's block scratch (:mod:`.lanes`' layout: rows of BLOCK values, a column a
# character). What root_lanes reads: the centre of mass's error (x, y), 1.0 where the step is
# predicted, per leg 1.0 where it is held and its knee's and ankle's shares of the mass ...
_R_ERROR, _R_PREDICTED, _R_HELD, _R_SHARES = 0, 2, 3, 5  # (held: leg s at + s; shares + 2 s)
# ... its hip, knee and ankle (leg s at + 3 s), its frame's y and z axes, its bones' lengths
# (leg s at + s), its footprint and whether it is in contact ...
_R_HIP, _R_KNEE, _R_ANKLE, _R_AXIS_Y, _R_AXIS_Z = 9, 15, 21, 27, 33
_R_UPPER, _R_LOWER, _R_FOOTPRINT, _R_CONTACT = 39, 41, 43, 49
# ... what it writes (the root's move, m), and 1.0 where a character waits for it (solve_rows).
_R_MOVE, R_WAITING = 51, 54
#: Rows of a block's root scratch (:func:`root_scratch`).
ROOT_SCRATCH_ROWS = 55


def root_scratch(n: int) -> F64:
    """The scratch :func:`solve_root` needs for ``n`` rows: (n // BLOCK + 1, a block's
    ROOT_SCRATCH_ROWS rows of BLOCK, flat), not zeroed: the chunk of rows from ``lo`` uses the
    block scratch ``lo // BLOCK`` alone (so chunks of at least :data:`.lanes.BLOCK` rows never
    share one), and :func:`.solve.solve_rows` zeroes it."""
    return np.empty((n // BLOCK + 1, ROOT_SCRATCH_ROWS * BLOCK))


@jit(inline="always")
def gather_root(c: int, dec: DecodedArrays, g: Goals, w: Winners, b: Bodies, t: Tables,
                ex: float, ey: float, tolerance_m: float, predicted: bool, scratch: F64,
                j: Column) -> None:
    """What :func:`root_lanes` needs of character ``c`` (its centre of mass's error ``ex``,
    ``ey`` m) into column ``j`` of ``scratch``: its legs as they are, which are held
    (:func:`held_legs`, where ``predicted``) and their shares of the mass."""
    p = dec.positions[c]
    held = held_legs(c, dec.positions, g, w, t, tolerance_m) if predicted else 0
    total = 0.0
    if predicted:
        for s in range(b.masses.shape[1]):
            total += b.masses[c, s]
    scratch[at(_R_ERROR, j)], scratch[at(_R_ERROR + 1, j)] = ex, ey
    scratch[at(_R_PREDICTED, j)] = 1.0 if predicted else 0.0
    lengths_row = b.lengths[c]
    for li in range(2):
        knee_share = ankle_share = 0.0
        if (held >> li) & 1:  # (the same for the step's three moves: once)
            knee_share, ankle_share = leg_shares(c, b, t, li, total)
        scratch[at(_R_HELD + li, j)] = 1.0 if (held >> li) & 1 else 0.0
        scratch[at(_R_SHARES + 2 * li, j)] = knee_share
        scratch[at(_R_SHARES + 2 * li + 1, j)] = ankle_share
        joints = t.limb_joint[li]
        put3(scratch, _R_HIP + 3 * li, j, load3(p[joints[0]]))
        put3(scratch, _R_KNEE + 3 * li, j, load3(p[joints[1]]))
        put3(scratch, _R_ANKLE + 3 * li, j, load3(p[joints[2]]))
        frame = load_frame(dec.leg2world[c, li])
        put3(scratch, _R_AXIS_Y + 3 * li, j, frame[1])
        put3(scratch, _R_AXIS_Z + 3 * li, j, frame[2])
        scratch[at(_R_UPPER + li, j)] = lengths_row[t.limb_length[li, 0]]
        scratch[at(_R_LOWER + li, j)] = lengths_row[t.limb_length[li, 1]]
        put3(scratch, _R_FOOTPRINT + 3 * li, j, load3(b.footprint[c, li]))
        scratch[at(_R_CONTACT + li, j)] = 1.0 if b.in_contact[c, li] else 0.0


@jit(inline="always")
def leg_reach(scratch: F64, j: Column, s: int, leg_extension: float) -> float:
    """The farthest (m) column ``j``'s leg ``s`` reaches from its hip: ``leg_extension`` of
    its thigh + shank."""
    reach: float = leg_extension * (scratch[at(_R_UPPER + s, j)] + scratch[at(_R_LOWER + s, j)])
    return reach


@jit(inline="always")
def lowering_lanes(scratch: F64, j: Column, sx: float, sy: float, leg_extension: float) -> float:
    """How far down (m, <= 0) column ``j``'s root must go with a horizontal move (``sx``,
    ``sy``) so each planted leg still reaches its footprint. Mirrors ``_Solve._with_lowering``
    (no branch: a loop over the block runs it on the vector units)."""
    sz = 0.0
    for s in range(2):
        # Mirrors ground_adapt.vertical_slack_for_reach for this hip once shifted.
        hip = col3(scratch, _R_HIP + 3 * s, j)
        hx, hy, hz = hip[0] + sx, hip[1] + sy, hip[2] + 0.0
        reach = leg_reach(scratch, j, s, leg_extension)
        fx, fy, fz = col3(scratch, _R_FOOTPRINT + 3 * s, j)
        horizontal = math.sqrt((hx - fx) ** 2 + (hy - fy) ** 2)
        needed = fz + math.sqrt(max(reach**2 - horizontal**2, 0.0)) - hz
        sz = min(sz, min(needed, 0.0) if scratch[at(_R_CONTACT + s, j)] != 0.0 else 0.0)
    return sz


@jit(inline="always")
def knee_bend(scratch: F64, j: Column, s: int, move: Vec3) -> Vec3:
    """How far column ``j``'s leg ``s``'s knee goes when the root moves by ``move`` and its
    ankle stays (:func:`middle_after_root_move`; the frame's x axis is not used)."""
    axis_y, axis_z = col3(scratch, _R_AXIS_Y + 3 * s, j), col3(scratch, _R_AXIS_Z + 3 * s, j)
    moved = middle_after_root_move(col3(scratch, _R_HIP + 3 * s, j),
                                   col3(scratch, _R_ANKLE + 3 * s, j), (axis_y, axis_y, axis_z),
                                   scratch[at(_R_UPPER + s, j)], scratch[at(_R_LOWER + s, j)],
                                   move)
    return sub(moved, col3(scratch, _R_KNEE + 3 * s, j))


@jit(inline="always")
def newton_leg(scratch: F64, j: Column, s: int, move: Vec3,
               leg_extension: float) -> tuple[float, float, bool]:
    """Leg ``s``'s part in the centre of mass's move when column ``j``'s root moves by
    ``move`` (x, y: its knee share follows the knee, its ankle share stays), and whether its
    ankle stays within the leg's reach."""
    knee_share = scratch[at(_R_SHARES + 2 * s, j)]
    ankle_share = scratch[at(_R_SHARES + 2 * s + 1, j)]
    bend = knee_bend(scratch, j, s, move)
    to_ankle = sub(sub(col3(scratch, _R_ANKLE + 3 * s, j), col3(scratch, _R_HIP + 3 * s, j)),
                   move)
    reach = leg_reach(scratch, j, s, leg_extension)
    return (knee_share * bend[0] - (knee_share + ankle_share) * move[0],
            knee_share * bend[1] - (knee_share + ankle_share) * move[1],
            math.sqrt(dot(to_ankle, to_ankle)) <= reach * (1.0 + 1e-9))


# A call (one compiled body for a block's loop and a character's later steps), not inlined.
@jit()
def root_lanes(scratch: F64, start: Column, stop: Column, root_gain: float,
               leg_extension: float) -> None:
    """The root's move (m, into its rows) of each column ``start:stop`` of a root scratch
    (:func:`gather_root`), in a loop over them that runs on the vector units: the move bringing
    the centre of mass by its error once the next pass has re-planted the held legs, where
    predicted (else the error times ``root_gain``), lowered so each planted leg still reaches
    its footprint. Mirrors ``_Solve.root_move`` and ``_Solve._with_lowering`` (the centre of
    mass moves with the root but for the held legs: their knees' shares follow the knees,
    their ankles' stay). Every case is computed and the one that applies chosen (selects, no
    branch), with the scalar step's operations in its order: the same bits in a lane or
    alone."""
    h = ROOT_PROBE_M
    for k in range(start, stop):
        j = Column(k)  # (the same type: for mypy, which takes k for an int)
        ex, ey = scratch[at(_R_ERROR, j)], scratch[at(_R_ERROR + 1, j)]
        held0, held1 = scratch[at(_R_HELD, j)] != 0.0, scratch[at(_R_HELD + 1, j)] != 0.0
        knee0, ankle0 = scratch[at(_R_SHARES, j)], scratch[at(_R_SHARES + 1, j)]
        knee1, ankle1 = scratch[at(_R_SHARES + 2, j)], scratch[at(_R_SHARES + 3, j)]
        # The Jacobian from two probes of the root, along x and along y (over the probe). A leg
        # not held is computed and not counted: its knee share follows its knee, its ankle
        # share stays (the probe's bend minus the probe itself).
        lx, ly = knee_bend(scratch, j, 0, (h, 0.0, 0.0)), knee_bend(scratch, j, 0, (0.0, h, 0.0))
        rx, ry = knee_bend(scratch, j, 1, (h, 0.0, 0.0)), knee_bend(scratch, j, 1, (0.0, h, 0.0))
        ax, ay, bx, by = h, 0.0, 0.0, h
        ax = ax + (knee0 * lx[0] - (knee0 + ankle0) * h) if held0 else ax
        ay = ay + (knee0 * lx[1] - (knee0 + ankle0) * 0.0) if held0 else ay
        bx = bx + (knee0 * ly[0] - (knee0 + ankle0) * 0.0) if held0 else bx
        by = by + (knee0 * ly[1] - (knee0 + ankle0) * h) if held0 else by
        ax = ax + (knee1 * rx[0] - (knee1 + ankle1) * h) if held1 else ax
        ay = ay + (knee1 * rx[1] - (knee1 + ankle1) * 0.0) if held1 else ay
        bx = bx + (knee1 * ry[0] - (knee1 + ankle1) * 0.0) if held1 else bx
        by = by + (knee1 * ry[1] - (knee1 + ankle1) * h) if held1 else by
        ax, ay, bx, by = ax / h, ay / h, bx / h, by / h
        det = ax * by - bx * ay
        # Newton's step, whose predicted move corrects it once where the Jacobian is firm and
        # every held ankle stays within reach.
        nx, ny = (by * ex - bx * ey) / det, (ax * ey - ay * ex) / det
        move = (nx, ny, lowering_lanes(scratch, j, nx, ny, leg_extension))
        mx0, my0, within0 = newton_leg(scratch, j, 0, move, leg_extension)
        mx1, my1, within1 = newton_leg(scratch, j, 1, move, leg_extension)
        mx = nx + mx0 if held0 else nx
        my = ny + my0 if held0 else ny
        mx = mx + mx1 if held1 else mx
        my = my + my1 if held1 else my
        within = ((scratch[at(_R_PREDICTED, j)] != 0.0) & (det > MIN_ROOT_JACOBIAN)
                  & (within0 | (not held0)) & (within1 | (not held1)))
        dx, dy = ex - mx, ey - my
        sx = nx + (by * dx - bx * dy) / det if within else ex * root_gain
        sy = ny + (ax * dy - ay * dx) / det if within else ey * root_gain
        put3(scratch, _R_MOVE, j, (sx, sy, lowering_lanes(scratch, j, sx, sy, leg_extension)))


@jit(inline="always")
def move_root(c: int, pose: PoseArrays, dec: DecodedArrays, b: Bodies, scratch: F64,
              j: Column) -> None:
    """Move character ``c``'s root (pose ``root_position``) and every decoded joint by the
    move :func:`root_lanes` left in column ``j``."""
    sx, sy, sz = col3(scratch, _R_MOVE, j)
    unit = leg_length(b.lengths[c])
    pose.root_position[c, 0] += sx / unit
    pose.root_position[c, 1] += sy / unit
    pose.root_position[c, 2] += sz / unit
    p = dec.positions[c]
    for joint in range(p.shape[0]):
        p[joint, 0] += sx
        p[joint, 1] += sy
        p[joint, 2] += sz


@jit(inline="always")
def solve_root(c: int, pose: PoseArrays, dec: DecodedArrays, g: Goals, w: Winners, b: Bodies,
               t: Tables, ex: float, ey: float, com_tolerance_m: float, tolerance_m: float,
               root_gain: float, leg_extension: float, predicted: bool, scratch: F64,
               j: Column, wait: bool) -> float:
    """Mirrors ``ecs_anim.solver.shell._Solve.root`` for character ``c`` (in place), whose
    :func:`com_shortfall` is (``ex``, ``ey``) (m; measured by the caller on the joints as they
    are): returns its size. ``leg_extension``: the longest a planted leg stretches, as a share
    of thigh + shank; ``predicted``: the character has no goal that keeps it iterating
    (``_Solve.predicted``: else the root moves by the error times ``root_gain``). The step
    goes through column ``j`` of a root scratch (:func:`root_scratch`); with ``wait`` it is
    only gathered there (the caller computes its block's columns together, :func:`root_lanes`,
    then :func:`move_root`)."""
    size = math.sqrt(ex * ex + ey * ey)
    if not size > 0.1 * com_tolerance_m:
        return size
    gather_root(c, dec, g, w, b, t, ex, ey, tolerance_m, predicted, scratch, j)
    if not wait:
        root_lanes(scratch, j, j + Column(1), root_gain, leg_extension)
        move_root(c, pose, dec, b, scratch, j)
    return size
