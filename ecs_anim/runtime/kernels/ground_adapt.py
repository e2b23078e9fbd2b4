"""Compiled ground adaptation (paper §7): the whole of ``GroundAdapt.run``, by blocks of characters.

Mirrors ``systems.ground_adapt.GroundAdapt.run`` (footprints laid on the sole point each foot
stands on and moved as the foot rolls, the motion's floor following the supporting feet, free
feet lifted clear of the ground, the toes pitched onto it) with :func:`ecs_anim.core.ground_adapt.adapt_keeping_heels_up`,
:func:`~ecs_anim.core.ground_adapt.adapt_to_ground` and
:func:`~ecs_anim.core.ground_adapt.vertical_slack_for_reach`, on a built-in ground given as its
:class:`~ecs_anim.core.ground.GroundDescription` arrays.

Every decision the numpy code takes for the whole batch (another heel pass, the toe passes) is
taken here per character, so a character's result never depends on who else is in the batch.
By blocks of :data:`.lanes.BLOCK` characters (:func:`ground_adapt_rows`): the motion's pelvis
and legs decoded (:func:`decode_lanes`), the legs' first re-aiming (:func:`reaim_lanes`), the
ground's queries (:func:`heights_lanes`) and the feet's secant passes (:func:`pitch_lanes`) in
loops over the block that run on the vector units, the rest (footprints, the pitches' first
steps, the heel checks) row by row; a row's result is the same, to the bit, in a vector lane
or alone.

Length indices are literals (numba's cache keys on this file's source); an import-time
check pins them to the skeleton.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core import ground_adapt as reference
from ecs_anim.core.skeleton import LENGTH_INDEX as L
from ecs_anim.runtime.kernels.decode import LegPoseArrays, two_bone_middle
from ecs_anim.runtime.kernels.ground import (
    BUMPS,
    PLANE,
    SLOPE,
    bumps_height,
    bumps_in_domain,
    height_at,
    height_near,
    near_known,
    smooth,
)
from ecs_anim.runtime.kernels.lanes import (
    BLOCK,
    Column,
    distal_frames_lanes,
    quat_from_matrix_lanes,
    rotation_between_lanes,
)
from ecs_anim.runtime.kernels.lanes import at as _at
from ecs_anim.runtime.kernels.lanes import col3 as _col3
from ecs_anim.runtime.kernels.lanes import col_frame as _col_frame
from ecs_anim.runtime.kernels.lanes import put3 as _put3
from ecs_anim.runtime.kernels.lanes import put_frame as _put_frame
from ecs_anim.runtime.kernels.vec import (
    F64,
    Frame,
    Vec3,
    add,
    add_scaled,
    in_frame,
    jit,
    load3,
    matmul,
    matrix_from_quat,
    norm,
    scale,
    store3,
    sub,
    to_world,
    transpose,
)

I64 = NDArray[np.int64]
B1 = NDArray[np.bool_]
#: A ground's description: (kinds, params, grid) of :class:`ecs_anim.core.ground.GroundDescription`.
GroundArrays = tuple[I64, F64, F64]

# Lengths of side s (0 left, 1 right) are these plus s.
_L_PELVIS, _L_THIGH, _L_SHANK, _L_FOOT, _L_ANKLE_HEIGHT = 0, 2, 4, 6, 8
assert L["pelvis_l"] == _L_PELVIS and L["pelvis_r"] == _L_PELVIS + 1
assert (L["thigh_l"], L["shank_l"], L["foot_l"], L["ankle_height_l"], L["thigh_r"],
        L["foot_r"], L["ankle_height_r"]) \
    == (_L_THIGH, _L_SHANK, _L_FOOT, _L_ANKLE_HEIGHT, _L_THIGH + 1, _L_FOOT + 1,
        _L_ANKLE_HEIGHT + 1)
#: The sole rolls of :mod:`ecs_anim.core.ground_adapt`, as literals for the same reason.
HEEL_ROLL, BALL_ROLL = 0.25, 0.75
assert (HEEL_ROLL, BALL_ROLL) == (reference.HEEL_ROLL, reference.BALL_ROLL)
MAX_LOWERING_LEAN_SIN, MAX_ROOT_FOLLOW_PER_REACH = 0.8660254037844386, 0.25
assert (MAX_LOWERING_LEAN_SIN, MAX_ROOT_FOLLOW_PER_REACH) \
    == (reference.MAX_LOWERING_LEAN_SIN, reference.MAX_ROOT_FOLLOW_PER_REACH)
TOE_TOLERANCE_M, MIN_SECANT_RATIO, MAX_SECANT_RATIO = 1e-9, 0.5, 2.0
assert (TOE_TOLERANCE_M, MIN_SECANT_RATIO, MAX_SECANT_RATIO) \
    == (reference.TOE_TOLERANCE_M, reference.MIN_SECANT_RATIO, reference.MAX_SECANT_RATIO)


#: No point whose ground is known (:func:`.ground.height_near`).
_UNKNOWN = (math.nan, math.nan, math.nan)


@jit(inline="always")
def _height(kinds: I64, params: F64, grid: F64, p: Vec3) -> float:
    """The ground's height under the point ``p`` (m)."""
    return height_at(p[0], p[1], kinds, params, grid)


@jit()
def vertical_slack_for_reach(hip: Vec3, ankle_target: Vec3, reach: float) -> float:
    """Mirrors :func:`ecs_anim.core.ground_adapt.vertical_slack_for_reach` for one leg (m)."""
    dx, dy = hip[0] - ankle_target[0], hip[1] - ankle_target[1]
    horizontal = math.sqrt(dx * dx + dy * dy)
    vertical = math.sqrt(max(reach**2 - horizontal**2, 0.0))
    return ankle_target[2] + vertical - hip[2]


@jit(inline="always")
def horizontal_reach_excess(hip: Vec3, ankle_target: Vec3, reach: float) -> tuple[float, float]:
    """Mirrors :func:`ecs_anim.core.ground_adapt.horizontal_reach_excess` for one leg: (x, y)
    m."""
    dx, dy = ankle_target[0] - hip[0], ankle_target[1] - hip[1]
    horizontal = math.sqrt(dx * dx + dy * dy)
    vertical = hip[2] - ankle_target[2]
    at_this_height = math.sqrt(max(reach**2 - vertical**2, 0.0))
    allowed = max(MAX_LOWERING_LEAN_SIN * reach, at_this_height)
    excess = min(max(horizontal - allowed, 0.0), MAX_ROOT_FOLLOW_PER_REACH * reach) \
        / max(horizontal, 1e-12)
    return excess * dx, excess * dy


# The scratch of ground_adapt_rows: a block's, one column a character (flat, rows of BLOCK).
# What the motion's decode (decode_lanes) reads: the pose (the root position, leg frames and
# fractions in the rows the re-aiming writes them to later), the heading's cosine and sine ...
_S_HEADING, _S_PELVIS_LOCAL, _S_HIP_DIR, _S_PELVIS_LENGTH = 115, 117, 121, 127
# ... what it writes and the legs' re-aiming (reaim_lanes) reads ...
_S_HIP, _S_PELVIS, _S_P2W, _S_L2W = 0, 6, 9, 18  # hips (side s at + 3 s), the pelvis, frames
_S_THIGH, _S_SHANK, _S_FOOT, _S_LEG = 36, 38, 40, 42  # lengths (side s at + s), leg length
_S_TARGET, _S_WEIGHT, _S_ROOT_HEIGHT, _S_FOOT_DIR = 43, 49, 51, 52
# ... what the re-aiming writes (the pose's leg frames and fractions, root position; the legs
# decoded: the motion's ankles and toes there before it) ...
_S_LEG_FRAME, _S_FRACTION, _S_ROOT, _S_ANKLE, _S_TOE, _S_SHANK2W = 58, 66, 68, 71, 77, 83
# ... and what a row carries from before the re-aiming to after it (the feet's lengths and
# directions: the decode's, then those the last pitch starts from).
_S_UNDER, _S_KNOWN, _S_DIR, _S_FOOT_LENGTH = 101, 103, 109, 129
#: The most ground queries a row asks between two answers (:func:`heights_lanes`): each foot's
#: three in :func:`_lay` (ground_adapt_after asks one a foot).
QUERIES_PER_ROW = 6
#: The block's feet being pitched (:func:`pitch_lanes`) ask theirs from this query on (one a
#: foot, after the rows' QUERIES_PER_ROW).
PITCH_QUERIES = QUERIES_PER_ROW * BLOCK
# The block's ground queries: their x, y and the ground's height under them (query k of each
# in column k of the rows from these on, QUERIES_PER_ROW + 2 rows of BLOCK each) ...
_S_Q_X = 131
_S_Q_Y = _S_Q_X + QUERIES_PER_ROW + 2
_S_Q_HEIGHT = _S_Q_Y + QUERIES_PER_ROW + 2
# ... and which query answers each foot (side s at + s): under the motion's ankle and toe (a
# foot not planted: its target's) and under the end of a foot pitched (its first end); -1:
# none asked.
_S_Q_ANKLE = _S_Q_HEIGHT + QUERIES_PER_ROW + 2
_S_Q_TOE, _S_Q_END = _S_Q_ANKLE + 2, _S_Q_ANKLE + 4
# The feet of a block still being pitched (pitch_lanes), entry k of each field in column k of
# its two rows (2 * BLOCK entries: both feet of each row): the joint the foot turns about, the
# horizontal heading of its direction, its rise (the other end's distance along it, signed),
# the clearance wanted there; the secant's state (the direction's z and the deficit, now and
# at the last pass); where the last pass put the direction and the other end's height; the
# foot (2 column + side) ...
_S_P_ORIGIN = _S_Q_END + 2  # x, y, z at + 2, + 4
_S_P_HEADING = _S_P_ORIGIN + 6  # x, y at + 2
_S_P_RISE, _S_P_CLEARANCE, _S_P_DZ, _S_P_DEFICIT = (_S_P_HEADING + 4 + 2 * k for k in range(4))
_S_P_LAST_DZ, _S_P_LAST_DEFICIT, _S_P_DX, _S_P_DY = (_S_P_DEFICIT + 2 + 2 * k for k in range(4))
_S_P_END_Z, _S_P_FOOT = _S_P_DY + 2, _S_P_DY + 4
# ... and each foot's pitch (side s's direction at + 3 s, the ground under its other end at
# + s): the direction it starts from and its first end's ground until pitch_lanes turns it.
_S_PITCHED, _S_PITCHED_GROUND = _S_P_FOOT + 2, _S_P_FOOT + 8
# Which query answers each foot's blended target (side s at + s; from PITCH_QUERIES on, -1:
# none asked, its ground known).
_S_Q_BLEND = _S_PITCHED_GROUND + 2
# The re-aimed feet's directions (side s at + 3 s; their lengths: _S_FOOT_LENGTH's rows).
_S_AXIS = _S_Q_BLEND + 2
# The planted feet's pitch_lanes entries before they are gathered to the front (foot s of
# column j as entry j + BLOCK s: pitch_planted_lanes, planted_entries), each field this many
# rows after the entry's.
_STAGED = _S_AXIS + 6 - _S_P_ORIGIN
#: Rows of a block's scratch (:func:`ground_scratch`).
GROUND_SCRATCH_ROWS = _S_P_FOOT + 2 + _STAGED


def ground_scratch(n: int) -> F64:
    """The scratch :func:`ground_adapt_rows` needs for ``n`` rows: (n // BLOCK + 1, a block's
    GROUND_SCRATCH_ROWS rows of BLOCK, flat). The chunk of rows from ``lo`` uses the block
    scratch ``lo // BLOCK`` for each of its blocks in turn (so chunks of at least
    :data:`.lanes.BLOCK` rows, ``over_chunks``' ``rows_per_thread``, never share one; one
    thread touches only the first: 59 KiB)."""
    return np.empty((n // BLOCK + 1, GROUND_SCRATCH_ROWS * BLOCK))


@jit(inline="always")
def _below_hip_lanes(scratch: F64, j: Column, s: int, hip: Vec3, leg2world: Frame,
                     fraction: float, with_shank: bool) -> None:
    """:func:`.decode.leg_below_hip` of side ``s`` of column ``j`` (the same operations, without
    branches), from its ``hip``, ``leg2world`` and fraction: the ankle, toe and (with
    ``with_shank``, a literal) shank2world into the column."""
    thigh, shank = scratch[_at(_S_THIGH + s, j)], scratch[_at(_S_SHANK + s, j)]
    knee, ankle = two_bone_middle(leg2world, hip, thigh, shank, fraction * (thigh + shank))
    shank2world = distal_frames_lanes(leg2world, knee, ankle)
    toe = add(ankle, scale(to_world(shank2world, _col3(scratch, _S_FOOT_DIR + 3 * s, j)),
                           scratch[_at(_S_FOOT + s, j)]))
    _put3(scratch, _S_ANKLE + 3 * s, j, ankle)
    _put3(scratch, _S_TOE + 3 * s, j, toe)
    if with_shank:
        _put_frame(scratch, _S_SHANK2W + 9 * s, j, shank2world)


@jit(inline="always")
def _decode_leg_lanes(scratch: F64, j: Column, s: int, pelvis: Vec3, pelvis2world: Frame) -> None:
    """Leg ``s`` of :func:`decode_lanes` (:func:`.decode.decode_legs_row`'s, the same
    operations): its hip, leg2world, ankle, toe, and the foot's length and direction
    (:func:`_foot_axis`) into column ``j``."""
    hip = add(pelvis, scale(to_world(pelvis2world, _col3(scratch, _S_HIP_DIR + 3 * s, j)),
                            scratch[_at(_S_PELVIS_LENGTH + s, j)]))
    r = _S_LEG_FRAME + 4 * s
    local = (scratch[_at(r, j)], scratch[_at(r + 1, j)], scratch[_at(r + 2, j)],
             scratch[_at(r + 3, j)])
    leg2world = matmul(pelvis2world, matrix_from_quat(local))
    _put3(scratch, _S_HIP + 3 * s, j, hip)
    _put_frame(scratch, _S_L2W + 9 * s, j, leg2world)
    _below_hip_lanes(scratch, j, s, hip, leg2world, scratch[_at(_S_FRACTION + s, j)], False)
    foot, d = _foot_axis(_col3(scratch, _S_ANKLE + 3 * s, j), _col3(scratch, _S_TOE + 3 * s, j))
    scratch[_at(_S_FOOT_LENGTH + s, j)] = foot
    _put3(scratch, _S_DIR + 3 * s, j, d)


# A call, not inlined (as reaim_lanes).
@jit()
def decode_lanes(scratch: F64, start: Column, stop: Column) -> None:
    """Mirrors :func:`.decode.decode_legs_row` (the pose on the character's body as the motion
    gives it: the pelvis and legs) for the columns ``start:stop`` of a ground scratch, in a
    loop over them that runs on the vector units; the same bits (the heading's cosine and
    sine given, :func:`.vec.rot_z`'s)."""
    for k in range(start, stop):
        j = Column(k)  # (the same type: for mypy, which takes k for an int)
        cos_h, sin_h = scratch[_at(_S_HEADING, j)], scratch[_at(_S_HEADING + 1, j)]
        r = _S_PELVIS_LOCAL
        local = (scratch[_at(r, j)], scratch[_at(r + 1, j)], scratch[_at(r + 2, j)],
                 scratch[_at(r + 3, j)])
        pelvis2world = matmul(((cos_h, sin_h, 0.0), (-sin_h, cos_h, 0.0), (0.0, 0.0, 1.0)),
                              matrix_from_quat(local))
        # .decode.leg_length's sum
        leg = 0.5 * (scratch[_at(_S_THIGH, j)] + scratch[_at(_S_SHANK, j)]
                     + scratch[_at(_S_THIGH + 1, j)] + scratch[_at(_S_SHANK + 1, j)])
        pelvis = scale(_col3(scratch, _S_ROOT, j), leg)
        _put3(scratch, _S_PELVIS, j, pelvis)
        _put_frame(scratch, _S_P2W, j, pelvis2world)
        _decode_leg_lanes(scratch, j, 0, pelvis, pelvis2world)
        _decode_leg_lanes(scratch, j, 1, pelvis, pelvis2world)


@jit(inline="always")
def _turn_leg_lanes(scratch: F64, j: Column, s: int, hip: Vec3, world2pelvis: Frame,
                    reach: float) -> None:
    """One leg of :func:`reaim_lanes`: leg ``s`` of column ``j`` turned from its motion's
    frame towards its target from its new ``hip``; its frame (in the pelvis, a quaternion)
    and fraction, the leg decoded below the hip, and the foot's length and direction
    (:func:`_foot_axis`), into the column."""
    leg2world = _col_frame(scratch, _S_L2W + 9 * s, j)
    thigh, shank = scratch[_at(_S_THIGH + s, j)], scratch[_at(_S_SHANK + s, j)]
    to_target = sub(_col3(scratch, _S_TARGET + 3 * s, j), hip)
    turned = matmul(rotation_between_lanes(leg2world[2], to_target), leg2world)
    q = quat_from_matrix_lanes(matmul(world2pelvis, turned))
    r = _S_LEG_FRAME + 4 * s
    scratch[_at(r, j)], scratch[_at(r + 1, j)], scratch[_at(r + 2, j)], scratch[_at(r + 3, j)] = q
    fraction = min(norm(to_target), reach) / (thigh + shank)
    scratch[_at(_S_FRACTION + s, j)] = fraction
    _below_hip_lanes(scratch, j, s, hip, turned, fraction, True)
    foot, d = _foot_axis(_col3(scratch, _S_ANKLE + 3 * s, j), _col3(scratch, _S_TOE + 3 * s, j))
    scratch[_at(_S_FOOT_LENGTH + s, j)] = foot
    _put3(scratch, _S_AXIS + 3 * s, j, d)


# A call (one compiled body for the block loop and a row's later passes), not inlined.
@jit()
def reaim_lanes(scratch: F64, start: Column, stop: Column, max_extension: float) -> None:
    """Mirrors :func:`ecs_anim.core.ground_adapt.adapt_to_ground` for the columns
    ``start:stop`` of a ground scratch (:func:`ground_scratch`), in a loop over them that runs
    on the vector units: the pelvis lowered as the legs in contact need (their targets and
    contact weights), moved horizontally where a leg cannot reach by that, the legs re-aimed
    from the motion's frames (hips, pelvis and leg frames as decoded before adaptation), and
    decoded below the hips (:func:`.decode.leg_below_hip`: ankles, toes, shank frames, and
    the feet's axes), as
    the pose's root position, leg frames and fractions written would decode, within rounding.
    The same bits in a vector lane or alone (no fastmath, no branch)."""
    for k in range(start, stop):
        j = Column(k)  # (the same type: for mypy, which takes k for an int)
        hip0, hip1 = _col3(scratch, _S_HIP, j), _col3(scratch, _S_HIP + 3, j)
        pelvis_now = _col3(scratch, _S_PELVIS, j)
        target0, target1 = _col3(scratch, _S_TARGET, j), _col3(scratch, _S_TARGET + 3, j)
        reach0 = max_extension * (scratch[_at(_S_THIGH, j)] + scratch[_at(_S_SHANK, j)])
        reach1 = max_extension * (scratch[_at(_S_THIGH + 1, j)] + scratch[_at(_S_SHANK + 1, j)])
        w0 = min(max(scratch[_at(_S_WEIGHT, j)], 0.0), 1.0)
        w1 = min(max(scratch[_at(_S_WEIGHT + 1, j)], 0.0), 1.0)
        root_height = scratch[_at(_S_ROOT_HEIGHT, j)]
        up = root_height - pelvis_now[2]
        ex0, ey0 = horizontal_reach_excess((hip0[0] + 0.0, hip0[1] + 0.0, hip0[2] + up),
                                           target0, reach0)
        ex1, ey1 = horizontal_reach_excess((hip1[0] + 0.0, hip1[1] + 0.0, hip1[2] + up),
                                           target1, reach1)
        shift_x = 0.0 + w0 * ex0 + w1 * ex1
        shift_y = 0.0 + w0 * ey0 + w1 * ey1
        needed0 = vertical_slack_for_reach((hip0[0] + shift_x, hip0[1] + shift_y, hip0[2] + up),
                                           target0, reach0)
        needed1 = vertical_slack_for_reach((hip1[0] + shift_x, hip1[1] + shift_y, hip1[2] + up),
                                           target1, reach1)
        lowest = min(w0 * min(needed0, 0.0), w1 * min(needed1, 0.0))
        pelvis_z = root_height + lowest
        shift = (shift_x, shift_y, pelvis_z - pelvis_now[2])
        world2pelvis = transpose(_col_frame(scratch, _S_P2W, j))
        _turn_leg_lanes(scratch, j, 0, add(hip0, shift), world2pelvis, reach0)
        _turn_leg_lanes(scratch, j, 1, add(hip1, shift), world2pelvis, reach1)
        leg = scratch[_at(_S_LEG, j)]
        scratch[_at(_S_ROOT, j)] = (pelvis_now[0] + shift_x) / leg
        scratch[_at(_S_ROOT + 1, j)] = (pelvis_now[1] + shift_y) / leg
        scratch[_at(_S_ROOT + 2, j)] = pelvis_z / leg


@jit(inline="always")
def _ask(scratch: F64, count: int, x: float, y: float) -> int:
    """The ground under (``x``, ``y``) asked as query ``count`` of the block
    (:func:`heights_lanes` answers it; ``count`` under :data:`QUERIES_PER_ROW` times the
    block's rows); returns the queries asked now."""
    scratch[_at(_S_Q_X, Column(count))] = x
    scratch[_at(_S_Q_Y, Column(count))] = y
    return count + 1


@jit(inline="always")
def _answer(scratch: F64, query: float) -> float:
    """The ground's height under query ``query`` of the block (m), once
    :func:`heights_lanes` has answered it."""
    return float(scratch[_at(_S_Q_HEIGHT, Column(int(query)))])


@jit()
def heights_lanes(scratch: F64, start: int, stop: int, kinds: I64, params: F64, grid: F64
                  ) -> None:
    """:func:`.ground.height_at` under the block's queries ``start:stop`` (:func:`_ask`) of
    ``scratch`` (a block's ground scratch, :func:`ground_scratch`), into their heights (m); the
    ground as described by :func:`ecs_anim.core.ground.describe`: ``kinds`` (parts,),
    ``params`` (parts, N_GROUND_PARAMS), ``grid`` the height grids' values. On a plane, a slope
    or bumps alone (the points within :func:`.ground.bumps_in_domain`) in a loop on the vector
    units, with the bits of ``height_at``'s."""
    lone = kinds[0] if kinds.shape[0] == 1 else -1  # the kind of a lone part
    if lone == PLANE or lone == SLOPE:
        z, grade_x, grade_y = params[0, 0], params[0, 1], params[0, 2]
        for k in range(start, stop):
            j = Column(k)
            slope = z + grade_x * scratch[_at(_S_Q_X, j)] + grade_y * scratch[_at(_S_Q_Y, j)]
            scratch[_at(_S_Q_HEIGHT, j)] = 0.0 + (z if lone == PLANE else slope)
        return
    if lone == BUMPS:
        z, amplitude, kx, ky = params[0, 0], params[0, 1], params[0, 2], params[0, 3]
        outside = 0
        for k in range(start, stop):
            j = Column(k)
            inside = bumps_in_domain(scratch[_at(_S_Q_X, j)], scratch[_at(_S_Q_Y, j)], kx, ky)
            outside += 0 if inside else 1
        if outside == 0:
            for k in range(start, stop):
                j = Column(k)
                scratch[_at(_S_Q_HEIGHT, j)] = 0.0 + bumps_height(
                    scratch[_at(_S_Q_X, j)], scratch[_at(_S_Q_Y, j)], z, amplitude, kx, ky)
            return
    for k in range(start, stop):
        j = Column(k)
        scratch[_at(_S_Q_HEIGHT, j)] = height_at(scratch[_at(_S_Q_X, j)],
                                                 scratch[_at(_S_Q_Y, j)], kinds, params, grid)


@jit(inline="always")
def _to_pitch(scratch: F64, count: int, j: Column, s: int, origin: Vec3, d: Vec3,
              foot: float, sign: float, clearance: float, ground: float) -> int:
    """Foot ``s`` of column ``j`` pitched as :func:`pitched_from` (the same arguments; ``count``
    feet of the block already waiting): its direction and first end's ground into the
    column's ``_S_PITCHED`` rows, and the foot made entry ``count`` of :func:`pitch_lanes` if
    that end is too low; returns the feet waiting now."""
    _put3(scratch, _S_PITCHED + 3 * s, j, d)
    scratch[_at(_S_PITCHED_GROUND + s, j)] = ground
    end = add_scaled(origin, d, sign * foot)
    deficit = ground + clearance - end[2]
    if not deficit > TOE_TOLERANCE_M:
        return count
    k = Column(count)
    _put_origin(scratch, 0, k, origin)
    scratch[_at(_S_P_RISE, k)], scratch[_at(_S_P_CLEARANCE, k)] = sign * foot, clearance
    _put_secant_start(scratch, 0, k, d, deficit)
    scratch[_at(_S_P_FOOT, k)] = 2 * j + s
    return count + 1


@jit(inline="always")
def _put_secant_start(scratch: F64, staged: int, k: Column, d: Vec3, deficit: float) -> None:
    """The secant's start of entry ``k`` of :func:`pitch_lanes` (its origin, rise, clearance
    and foot written apart; ``staged`` as :func:`_put_origin`): the foot's heading from its
    direction ``d``, and ``d``'s rise and the first ``deficit`` (m) as this and the last step's."""
    flat = max(math.sqrt(d[0] * d[0] + d[1] * d[1]), 1e-9)
    scratch[_at(_S_P_HEADING + staged, k)] = d[0] / flat
    scratch[_at(_S_P_HEADING + 2 + staged, k)] = d[1] / flat
    scratch[_at(_S_P_DZ + staged, k)], scratch[_at(_S_P_DEFICIT + staged, k)] = d[2], deficit
    scratch[_at(_S_P_LAST_DZ + staged, k)] = d[2]
    scratch[_at(_S_P_LAST_DEFICIT + staged, k)] = deficit


# The fields of a pitch_lanes entry that a pass carries to the next.
_PITCH_STATE = (_S_P_ORIGIN, _S_P_ORIGIN + 2, _S_P_ORIGIN + 4, _S_P_HEADING, _S_P_HEADING + 2,
                _S_P_RISE, _S_P_CLEARANCE, _S_P_DZ, _S_P_DEFICIT, _S_P_LAST_DZ,
                _S_P_LAST_DEFICIT, _S_P_FOOT)


@jit()
def pitch_lanes(scratch: F64, count: int, kinds: I64, params: F64, grid: F64, passes: int
                ) -> None:
    """:func:`pitched_from`'s secant passes for the ``count`` feet of a block made entries of
    ``scratch`` (a block's ground scratch) by :func:`_to_pitch` or :func:`planted_entries`,
    with the same bits: each pass a
    loop over the feet still too low that runs on the vector units, their ground asked at
    once (:func:`heights_lanes`), then those still too low gathered to the front (the others'
    direction and ground written into their columns' ``_S_PITCHED`` rows), at most
    ``passes`` times."""
    for turn in range(passes):
        if count == 0:
            return
        for e in range(count):
            k = Column(e)
            dz, deficit = scratch[_at(_S_P_DZ, k)], scratch[_at(_S_P_DEFICIT, k)]
            origin = (scratch[_at(_S_P_ORIGIN, k)], scratch[_at(_S_P_ORIGIN + 2, k)],
                      scratch[_at(_S_P_ORIGIN + 4, k)])
            next_dz, d, end = secant_step(dz, deficit, scratch[_at(_S_P_LAST_DZ, k)],
                                          scratch[_at(_S_P_LAST_DEFICIT, k)],
                                          scratch[_at(_S_P_RISE, k)],
                                          scratch[_at(_S_P_HEADING, k)],
                                          scratch[_at(_S_P_HEADING + 2, k)], origin)
            scratch[_at(_S_P_LAST_DZ, k)], scratch[_at(_S_P_LAST_DEFICIT, k)] = dz, deficit
            q = Column(PITCH_QUERIES) + k
            scratch[_at(_S_Q_X, q)], scratch[_at(_S_Q_Y, q)] = end[0], end[1]
            scratch[_at(_S_P_END_Z, k)] = end[2]
            scratch[_at(_S_P_DX, k)], scratch[_at(_S_P_DY, k)] = d[0], d[1]
            scratch[_at(_S_P_DZ, k)] = next_dz
        heights_lanes(scratch, PITCH_QUERIES, PITCH_QUERIES + count, kinds, params, grid)
        waiting = 0
        for e in range(count):
            k = Column(e)
            ground = scratch[_at(_S_Q_HEIGHT, Column(PITCH_QUERIES) + k)]
            deficit = ground + scratch[_at(_S_P_CLEARANCE, k)] - scratch[_at(_S_P_END_Z, k)]
            scratch[_at(_S_P_DEFICIT, k)] = deficit
            if deficit > TOE_TOLERANCE_M and turn + 1 < passes:
                for r in _PITCH_STATE:
                    scratch[_at(r, Column(waiting))] = scratch[_at(r, k)]
                waiting += 1
            else:
                foot = int(scratch[_at(_S_P_FOOT, k)])
                j, s = Column(foot // 2), foot % 2
                _put3(scratch, _S_PITCHED + 3 * s, j, (scratch[_at(_S_P_DX, k)],
                                                       scratch[_at(_S_P_DY, k)],
                                                       scratch[_at(_S_P_DZ, k)]))
                scratch[_at(_S_PITCHED_GROUND + s, j)] = ground
        count = waiting


@jit(inline="always")  # one call site
def adapt_keeping_heels_up(i: Column, c: int, pose: LegPoseArrays, scratch: F64, kinds: I64,
                           params: F64, grid: F64, is_smooth: bool, ankle_height: Vec3,
                           max_extension: float, heel_tolerance: float, passes: int) -> None:
    """Mirrors :func:`ecs_anim.core.ground_adapt.adapt_keeping_heels_up` for store row ``c``
    (column ``i`` of the scratch, whose first pass :func:`reaim_lanes` has made with the rest
    of its block): the ankle targets lifted (up to ``passes`` times, each a pass of
    :func:`reaim_lanes` on this column alone) while a heel would be more than
    ``heel_tolerance`` (m) under the ground; then the last pass's root position, leg frames
    and fractions written into row ``c`` of ``pose``. The ground's height under each target
    (the column's; lifting a target keeps its x, y): an ankle that reached its target is not
    asked about again on a smooth ground (``is_smooth``, :func:`.ground.height_near`).
    ``ankle_height`` (left, right, unused) m."""
    for lift in range(passes + 1):
        if lift > 0:
            reaim_lanes(scratch, i, i + Column(1), max_extension)
        if lift == passes:
            break
        t0, t1 = _col3(scratch, _S_TARGET, i), _col3(scratch, _S_TARGET + 3, i)
        a0, a1 = _col3(scratch, _S_ANKLE, i), _col3(scratch, _S_ANKLE + 3, i)
        d0 = height_near(a0[0], a0[1], (t0[0], t0[1], scratch[_at(_S_UNDER, i)]), is_smooth,
                         kinds, params, grid) + ankle_height[0] - a0[2]
        d1 = height_near(a1[0], a1[1], (t1[0], t1[1], scratch[_at(_S_UNDER + 1, i)]), is_smooth,
                         kinds, params, grid) + ankle_height[1] - a1[2]
        if not (d0 > heel_tolerance or d1 > heel_tolerance):
            break
        scratch[_at(_S_TARGET + 2, i)] = t0[2] + max(d0, 0.0)
        scratch[_at(_S_TARGET + 5, i)] = t1[2] + max(d1, 0.0)
    for s in range(2):
        r = _S_LEG_FRAME + 4 * s
        pose.leg_frame[c, s, 0], pose.leg_frame[c, s, 1] = scratch[_at(r, i)], scratch[_at(r + 1, i)]
        pose.leg_frame[c, s, 2], pose.leg_frame[c, s, 3] = scratch[_at(r + 2, i)], scratch[_at(r + 3, i)]
        pose.leg_fraction[c, s] = scratch[_at(_S_FRACTION + s, i)]
    store3(pose.root_position[c], _col3(scratch, _S_ROOT, i))


# Not inlined (nor planted_foot): a row calls them from several places, and inlining each copy
# tripled ground_adapt_rows's compile time (14 s of CPU, 43 s inlined) for 1-5 % of its run.
@jit()
def pitched(origin: Vec3, d: Vec3, foot: float, sign: float, clearance: float, kinds: I64,
            params: F64, grid: F64, passes: int) -> tuple[Vec3, float]:
    """Mirrors :func:`ecs_anim.core.ground_adapt.pitched`: the foot direction ``d`` (unit, world)
    turned in its vertical plane, at most ``passes`` times asking the ground again, until the
    foot's other end ``origin + sign * foot * d`` is ``clearance`` (m) above the ground or
    less than :data:`~ecs_anim.core.ground_adapt.TOE_TOLERANCE_M` under that; ``sign`` +1
    about the ankle (the toe end lifted), -1 about the ball (the ankle end). Each pass is a
    secant step (:func:`~ecs_anim.core.ground_adapt.pitch_slope`).
    Returns (that direction, the ground's height under the other end it puts the foot's at, m:
    asked once here, so the caller need not ask again)."""
    end = add_scaled(origin, d, sign * foot)
    return pitched_from(origin, d, foot, sign, clearance,
                        height_at(end[0], end[1], kinds, params, grid), kinds, params, grid,
                        passes)


@jit()
def pitched_from(origin: Vec3, d: Vec3, foot: float, sign: float, clearance: float,
                 ground: float, kinds: I64, params: F64, grid: F64, passes: int
                 ) -> tuple[Vec3, float]:
    """:func:`pitched`, the ground's height under the foot's first end
    (``origin + sign * foot * d``) given: ``ground`` (m)."""
    dz = d[2]
    end = add_scaled(origin, d, sign * foot)
    deficit = ground + clearance - end[2]
    last_dz, last_deficit = dz, deficit
    hx, hy = 0.0, 0.0  # the horizontal heading, once a pass needs it (most feet need none)
    for turn in range(passes):
        if not deficit > TOE_TOLERANCE_M:
            break
        if turn == 0:
            flat = max(math.sqrt(d[0] * d[0] + d[1] * d[1]), 1e-9)
            hx, hy = d[0] / flat, d[1] / flat
        next_dz, d, end = secant_step(dz, deficit, last_dz, last_deficit, sign * foot, hx, hy,
                                      origin)
        last_dz, last_deficit, dz = dz, deficit, next_dz
        ground = height_at(end[0], end[1], kinds, params, grid)
        deficit = ground + clearance - end[2]
    return d, ground


@jit(inline="always")
def secant_step(dz: float, deficit: float, last_dz: float, last_deficit: float, rise: float,
                hx: float, hy: float, origin: Vec3) -> tuple[float, Vec3, Vec3]:
    """One secant pass of a foot's pitch (:func:`pitched_from`, :func:`pitch_lanes`): the
    direction's new z from its last two (``dz``, ``last_dz``) and their ``deficit`` and
    ``last_deficit`` (m), the foot's ``rise`` (m: ``sign * foot``) and its horizontal heading
    (``hx``, ``hy``, unit). Returns (that z, the new direction, its other end ``origin + rise *
    direction``)."""
    slope = pitch_slope(dz, deficit, last_dz, last_deficit, rise)
    dz = min(max(dz - deficit / slope, -1.0), 1.0)
    along = math.sqrt(1.0 - dz * dz)
    d = (hx * along, hy * along, dz)
    return dz, d, add_scaled(origin, d, rise)


@jit(inline="always")
def pitch_slope(dz: float, deficit: float, last_dz: float, last_deficit: float,
                rise: float) -> float:
    """Mirrors :func:`ecs_anim.core.ground_adapt.pitch_slope` for one foot (m of deficit per
    unit of the direction's z); without branches (a loop of it runs on the vector units)."""
    flat = -rise
    step = dz - last_dz
    secant = (deficit - last_deficit) / step  # (not taken where step is 0)
    ratio = secant / flat
    steep_enough = (step != 0.0) & (MIN_SECANT_RATIO < ratio) & (ratio < MAX_SECANT_RATIO)
    return secant if steep_enough else flat


@jit()
def planted_foot(pivot: int, sole_point: Vec3, d: Vec3, foot: float, ankle_height: float,
                 ball: float, kinds: I64, params: F64, grid: F64, passes: int
                 ) -> tuple[Vec3, Vec3, tuple[float, float]]:
    """Mirrors :func:`ecs_anim.core.ground_adapt.planted_foot`: (ankle, foot direction) of a
    foot standing on ``sole_point`` (world, on the ground) with its heel (``pivot`` 0) or its
    ball (1), pitched as the motion's ``d`` unless that puts its other end under the ground;
    and the ground's heights (m) under its ankle and under its toe end (``ankle + foot * d``):
    the sole point's own under the end it stands on, the last one :func:`pitched` asked for
    under the other, so that nobody asks for them again."""
    if pivot == 0:
        ankle = (sole_point[0], sole_point[1], sole_point[2] + ankle_height)
        d, under_toe = pitched(ankle, d, foot, 1.0, ball, kinds, params, grid, passes)
        return ankle, d, (sole_point[2], under_toe)
    toe = (sole_point[0], sole_point[1], sole_point[2] + ball)
    d, under_ankle = pitched(toe, d, foot, -1.0, ankle_height, kinds, params, grid, passes)
    return add_scaled(toe, d, -foot), d, (under_ankle, sole_point[2])


@jit(inline="always")
def _pivot_wanted(roll: float, current: int) -> int:
    """The sole part the motion plants (``roll``: 0 heel, 1 ball, 0.5 both; see
    :data:`ecs_anim.core.ground_adapt.HEEL_ROLL`), else ``current``."""
    if roll < HEEL_ROLL:
        return 0
    if roll > BALL_ROLL:
        return 1
    return current


@jit(inline="always")
def _foot_target(ankle: Vec3, toe: Vec3, under_motion: tuple[float, float], planted_ankle: Vec3,
                 under_planted: float, w: float, ground_ref: float, ankle_height: float,
                 ball: float) -> tuple[Vec3, float, bool]:
    """One ankle's target in ``GroundAdapt.run`` before its heel is kept above the ground
    (:func:`_lift_target`), the ground's height under it (m) and whether that is to be asked
    (then NaN): the
    motion's free foot on the floor ``ground_ref`` (m), lifted where its heel or toe would be
    under the ground, blended towards where the planted foot puts it (``planted_ankle``, the
    ground ``under_planted`` it, m) by the contact weight ``w``; ``under_motion`` the ground's
    heights under ``ankle`` and ``toe`` (m).

    The ground is asked only where nobody has: a planted foot's target is its ankle (two
    queries fewer: where the free foot would be does not count), a free foot's is where the
    heel was asked about."""
    if w == 1.0:
        return planted_ankle, under_planted, False
    free = (ankle[0], ankle[1], ankle[2] + ground_ref)
    under_free = under_motion[0]
    need_heel = under_free + ankle_height - free[2]
    need_toe = under_motion[1] + ball - (toe[2] + ground_ref)
    free = (free[0], free[1], free[2] + max(0.0, max(need_heel, need_toe)))
    t = (free[0] + w * (planted_ankle[0] - free[0]),
         free[1] + w * (planted_ankle[1] - free[1]),
         free[2] + w * (planted_ankle[2] - free[2]))
    # (w == 0 leaves the point where it was asked about: (x + 0 * ...) is x)
    return t, under_free if w == 0.0 else math.nan, w != 0.0


@jit(inline="always")
def _lift_target(t: Vec3, under: float, ankle_height: float) -> Vec3:
    """An ankle's target ``t`` with its heel kept above the ground (``under`` it, m)."""
    return (t[0], t[1], t[2] + max(under + ankle_height - t[2], 0.0))


@jit(inline="always")
def _lay(c: int, s: int, j: Column, ankle: Vec3, toe: Vec3, foot: float, d: Vec3, w: float,
         sole_roll: F64, clip: I64, source_ankle_height: F64, footprint: F64, locked: B1,
         pivot: I64, leg: float, ankle_height: float, ball: float, kinds: I64, params: F64,
         grid: F64, scratch: F64, count: int) -> int:
    """Foot ``s`` of row ``c`` in ``GroundAdapt.run`` up to its pitch: its footprint laid
    where a contact starts (see :func:`_stand`), the ground under the first end of the foot
    standing on it asked (:func:`planted_foot`'s pitch), and a foot not planted the ground
    under the motion's ankle and toe (its target's, :func:`_foot_target`); a foot not in
    contact unlocked. ``foot`` (m), ``d`` (unit): the motion's ankle-to-toe length and
    direction (:func:`_foot_axis`). The queries from ``count`` on (column ``j``'s
    ``_S_Q_*``; at most three, :data:`QUERIES_PER_ROW` for both feet); returns the queries
    asked now."""
    scratch[_at(_S_Q_END + s, j)] = -1.0
    scratch[_at(_S_Q_ANKLE + s, j)], scratch[_at(_S_Q_TOE + s, j)] = -1.0, -1.0
    if w != 1.0:
        scratch[_at(_S_Q_ANKLE + s, j)], scratch[_at(_S_Q_TOE + s, j)] = count, count + 1
        count = _ask(scratch, _ask(scratch, count, ankle[0], ankle[1]), toe[0], toe[1])
    f = _foot_entry(j, s)
    scratch[_at(_S_P_FOOT + _STAGED, f)] = 2 * j + s
    if not w > 0.0:
        locked[c, s] = False
        # (pitch_planted_lanes turns every foot: no stale value in its arithmetic)
        _put_origin(scratch, _STAGED, f, (0.0, 0.0, 0.0))
        scratch[_at(_S_P_RISE + _STAGED, f)] = 0.0
        scratch[_at(_S_P_CLEARANCE + _STAGED, f)] = 0.0
        return count
    if not locked[c, s]:
        heel_up = ankle[2] - source_ankle_height[clip[c], s] * leg
        pivot[c, s] = _pivot_wanted(sole_roll[c, s], 0 if heel_up <= toe[2] - ball else 1)
        point = ankle if pivot[c, s] == 0 else toe
        store3(footprint[c, s], (point[0], point[1], _height(kinds, params, grid, point)))
        locked[c, s] = True
    # The foot's pitch as planted_foot's (pitch_planted_lanes): about its ankle on its heel,
    # its toe joint on its ball.
    heel = pivot[c, s] == 0
    origin = _pivot_point(pivot[c, s], load3(footprint[c, s]), ankle_height, ball)
    rise = (1.0 if heel else -1.0) * foot
    _put_origin(scratch, _STAGED, f, origin)
    scratch[_at(_S_P_RISE + _STAGED, f)] = rise
    scratch[_at(_S_P_CLEARANCE + _STAGED, f)] = ball if heel else ankle_height
    end = add_scaled(origin, d, rise)
    scratch[_at(_S_Q_END + s, j)] = count
    return _ask(scratch, count, end[0], end[1])


@jit(inline="always")
def _foot_entry(j: Column, s: int) -> Column:
    """The :func:`pitch_lanes` entry foot ``s`` of column ``j`` takes before the entries are
    gathered to the front (:func:`planted_entries`): side s's in the field's row s, so that a
    loop over the columns reads and writes each row contiguously."""
    return j + Column(BLOCK * s)


@jit(inline="always")
def _put_origin(scratch: F64, staged: int, k: Column, origin: Vec3) -> None:
    """The joint entry ``k`` of :func:`pitch_lanes` turns about (``staged``: 0, or
    ``_STAGED`` for a planted foot's entry before :func:`planted_entries`)."""
    for a in range(3):
        scratch[_at(_S_P_ORIGIN + 2 * a + staged, k)] = origin[a]


@jit(inline="always")
def _pivot_point(pivot: int, sole_point: Vec3, ankle_height: float, ball: float) -> Vec3:
    """The joint a foot standing on ``sole_point`` turns about (:func:`planted_foot`): its
    ankle on its heel (``pivot`` 0), its toe joint on its ball (1)."""
    return (sole_point[0], sole_point[1], sole_point[2] + (ankle_height if pivot == 0 else ball))


@jit(inline="always")
def _stand(c: int, s: int, j: Column, ankle: Vec3, d: Vec3, foot: float, w: float,
           sole_roll: F64, footprint: F64, pivot: I64, ankle_height: float, ball: float,
           switch: float, kinds: I64, params: F64, grid: F64, passes: int, scratch: F64
           ) -> tuple[Vec3, Vec3, tuple[float, float]]:
    """Foot ``s`` of row ``c`` in ``GroundAdapt.run`` once :func:`_lay` has laid it and
    :func:`pitch_planted_lanes` and :func:`pitch_lanes` pitched it (column ``j``): (ankle,
    foot direction, the ground's heights under that ankle and under the toe end (m), as
    :func:`planted_foot`) standing on its footprint, moved onto the other sole point where the
    foot has rolled onto it; the motion's (``ankle``, ``d``, NaN: not asked) for a foot not in
    contact.

    A contact's footprint is laid where the motion puts its planted point (the heel, the ball,
    or the lower of the two where the motion plants both), on the ground under it; it moves to
    the other point only once the foot has rolled onto it (within ``switch`` m of the ground),
    so the foot turns about the point it stands on and never jumps."""
    if not w > 0.0:
        return ankle, d, (math.nan, math.nan)
    # planted_foot, pitched by pitch_planted_lanes and pitch_lanes
    sole_point = load3(footprint[c, s])
    origin = _pivot_point(pivot[c, s], sole_point, ankle_height, ball)
    d, ground = _col3(scratch, _S_PITCHED + 3 * s, j), scratch[_at(_S_PITCHED_GROUND + s, j)]
    if pivot[c, s] == 0:
        a, under = origin, (sole_point[2], ground)
    else:
        a, under = add_scaled(origin, d, -foot), (ground, sole_point[2])
    want = _pivot_wanted(sole_roll[c, s], pivot[c, s])
    if want != pivot[c, s]:
        # The other sole point, and the ground under it as planted_foot asked for it.
        other = add_scaled(a, d, foot) if want == 1 else a
        ground = under[want]
        if other[2] - (ball if want == 1 else ankle_height) - ground <= switch:
            pivot[c, s] = want
            store3(footprint[c, s], (other[0], other[1], ground))
            a, d, under = planted_foot(want, load3(footprint[c, s]), d, foot, ankle_height,
                                       ball, kinds, params, grid, passes)
    return a, d, under


@jit(inline="always")
def _foot_axis(ankle: Vec3, toe: Vec3) -> tuple[float, Vec3]:
    """A foot's ankle-to-toe length (m, at least 1e-9) and direction (unit)."""
    foot = max(norm(sub(toe, ankle)), 1e-9)
    return foot, scale(sub(toe, ankle), 1.0 / foot)


@jit(inline="always")  # one call site
def gather_motion(i: Column, c: int, pose: LegPoseArrays, lengths: F64, scratch: F64) -> None:
    """What :func:`decode_lanes` and :func:`reaim_lanes` read of store row ``c``'s pose and
    lengths into column ``i`` of ``scratch`` (the heading's cosine and sine computed here:
    library calls, which LLVM does not vectorize)."""
    heading = pose.root_heading[c]
    scratch[_at(_S_HEADING, i)], scratch[_at(_S_HEADING + 1, i)] = math.cos(heading), \
        math.sin(heading)
    for a in range(4):
        scratch[_at(_S_PELVIS_LOCAL + a, i)] = pose.pelvis_local[c, a]
    _put3(scratch, _S_ROOT, i, load3(pose.root_position[c]))
    for s in range(2):
        _put3(scratch, _S_HIP_DIR + 3 * s, i, load3(pose.hip_dir[c, s]))
        for a in range(4):
            scratch[_at(_S_LEG_FRAME + 4 * s + a, i)] = pose.leg_frame[c, s, a]
        scratch[_at(_S_FRACTION + s, i)] = pose.leg_fraction[c, s]
        scratch[_at(_S_PELVIS_LENGTH + s, i)] = lengths[c, _L_PELVIS + s]
        scratch[_at(_S_THIGH + s, i)] = lengths[c, _L_THIGH + s]
        scratch[_at(_S_SHANK + s, i)] = lengths[c, _L_SHANK + s]
        scratch[_at(_S_FOOT + s, i)] = lengths[c, _L_FOOT + s]
        _put3(scratch, _S_FOOT_DIR + 3 * s, i, load3(pose.foot_dir[c, s]))


@jit(inline="always")  # one call site
def lay_feet(i: Column, c: int, lengths: F64, leg: F64, contact_weight: F64, sole_roll: F64,
             clip: I64, source_ankle_height: F64, footprint: F64, locked: B1, pivot: I64,
             kinds: I64, params: F64, grid: F64, ball_per_leg: float, scratch: F64,
             count: int) -> int:
    """Store row ``c``'s feet (column ``i`` of ``scratch``, the motion decoded there by
    :func:`decode_lanes`) laid and their queries asked from ``count`` on (:func:`_lay`);
    returns the queries asked now. Arguments as for :func:`ground_adapt_rows`."""
    leg_c = leg[c]
    for s in range(2):
        count = _lay(c, s, i, _col3(scratch, _S_ANKLE + 3 * s, i),
                     _col3(scratch, _S_TOE + 3 * s, i), scratch[_at(_S_FOOT_LENGTH + s, i)],
                     _col3(scratch, _S_DIR + 3 * s, i), contact_weight[c, s], sole_roll, clip,
                     source_ankle_height, footprint, locked, pivot, leg_c,
                     lengths[c, _L_ANKLE_HEIGHT + s], ball_per_leg * leg_c, kinds, params, grid,
                     scratch, count)
    return count


@jit(inline="always")
def _under_motion(scratch: F64, i: Column, s: int) -> tuple[float, float]:
    """The ground's heights under foot ``s``'s ankle and toe as the motion has them (column
    ``i``'s answered queries; NaN where not asked: a planted foot's), m."""
    ankle, toe = scratch[_at(_S_Q_ANKLE + s, i)], scratch[_at(_S_Q_TOE + s, i)]
    return (_answer(scratch, ankle) if ankle >= 0.0 else math.nan,
            _answer(scratch, toe) if toe >= 0.0 else math.nan)


@jit(inline="always")
def _first_pitch_lanes(scratch: F64, j: Column, s: int) -> None:
    """Foot ``s`` of column ``j`` in :func:`pitch_planted_lanes`."""
    f = _foot_entry(j, s)
    ground = scratch[_at(_S_PITCHED_GROUND + s, j)]
    d = _col3(scratch, _S_DIR + 3 * s, j)
    origin = (scratch[_at(_S_P_ORIGIN + _STAGED, f)], scratch[_at(_S_P_ORIGIN + 2 + _STAGED, f)],
              scratch[_at(_S_P_ORIGIN + 4 + _STAGED, f)])
    end = add_scaled(origin, d, scratch[_at(_S_P_RISE + _STAGED, f)])
    _put3(scratch, _S_PITCHED + 3 * s, j, d)
    _put_secant_start(scratch, _STAGED, f, d,
                      ground + scratch[_at(_S_P_CLEARANCE + _STAGED, f)] - end[2])


# A call, not inlined (as reaim_lanes).
@jit()
def pitch_planted_lanes(scratch: F64, start: Column, stop: Column) -> None:
    """The feet in contact of the columns ``start:stop`` of a ground scratch (laid by
    :func:`lay_feet`, their queries answered) pitched as :func:`planted_foot` pitches them on
    their footprints, up to the secant passes (:func:`_to_pitch`'s first step): each foot's
    direction and first end's ground into its column, its :func:`pitch_lanes` entry in place
    (:func:`_foot_entry`), in a loop over the columns that runs on the vector units; every
    foot is turned (those not in contact to no use), :func:`planted_entries` keeps the feet
    in contact still too low."""
    for k in range(start, stop):
        j = Column(k)
        for s in range(2):
            query = scratch[_at(_S_Q_END + s, j)]  # (-1: not in contact)
            scratch[_at(_S_PITCHED_GROUND + s, j)] = _answer(scratch, max(query, 0.0))
    for k in range(start, stop):
        j = Column(k)  # (the same type: for mypy, which takes k for an int)
        _first_pitch_lanes(scratch, j, 0)
        _first_pitch_lanes(scratch, j, 1)


@jit(inline="always")  # one call site
def planted_entries(scratch: F64, n: int) -> int:
    """The :func:`pitch_lanes` entries of :func:`pitch_planted_lanes` (a block's ``n``
    columns) whose foot is in contact and too low, gathered to the front in the order of
    their feet; returns how many."""
    count = 0
    for e in range(2 * n):
        k = _foot_entry(Column(e // 2), e % 2)
        in_contact = scratch[_at(_S_Q_END + e % 2, Column(e // 2))] >= 0.0
        if in_contact and scratch[_at(_S_P_DEFICIT + _STAGED, k)] > TOE_TOLERANCE_M:
            for r in _PITCH_STATE:
                scratch[_at(r, Column(count))] = scratch[_at(r + _STAGED, k)]
            count += 1
    return count


@jit(inline="always")  # one call site: a call per row, handed its arrays, costs
def ground_adapt_before(i: Column, c: int, lengths: F64, leg: F64, contact_weight: F64,
                        sole_roll: F64, footprint: F64, pivot: I64, ground_ref: F64,
                        kinds: I64, params: F64, grid: F64, follow: float,
                        ball_per_leg: float, switch_per_leg: float, toe_passes: int,
                        scratch: F64, count: int) -> int:
    """Mirrors ``GroundAdapt.run`` for store row ``c`` up to the legs' re-aiming, once its
    feet are laid (:func:`lay_feet`), their queries answered (:func:`heights_lanes`) and the
    feet in contact pitched (:func:`pitch_planted_lanes`, :func:`pitch_lanes`): the feet in contact
    planted, the floor moved, the ankles' targets (:func:`lift_targets` lifts them, the
    ground under a blended one asked from query ``PITCH_QUERIES + count`` on: at most two);
    what :func:`reaim_lanes` and :func:`ground_adapt_after` need into column ``i`` of
    ``scratch``. Returns the blends' queries asked now. Arguments as for
    :func:`ground_adapt_rows` (``kinds``, ``params``, ``grid``: the arrays of ``ground``;
    ``follow``: the share of the way to the ground under the feet the floor moves this tick,
    the same for every row)."""
    # The pose on the character's body as the motion gives it (decode_lanes).
    pelvis = _col3(scratch, _S_PELVIS, i)
    ankles = (_col3(scratch, _S_ANKLE, i), _col3(scratch, _S_ANKLE + 3, i))
    toes = (_col3(scratch, _S_TOE, i), _col3(scratch, _S_TOE + 3, i))
    leg_c = leg[c]
    ball = ball_per_leg * leg_c
    switch = switch_per_leg * leg_c
    ankle_height = (lengths[c, _L_ANKLE_HEIGHT], lengths[c, _L_ANKLE_HEIGHT + 1], 0.0)
    w = (contact_weight[c, 0], contact_weight[c, 1])
    # Each foot in contact stands on one sole point (its footprint, on the ground): the heel
    # or the ball, as the motion plants it.
    foot0, d0 = scratch[_at(_S_FOOT_LENGTH, i)], _col3(scratch, _S_DIR, i)
    foot1, d1 = scratch[_at(_S_FOOT_LENGTH + 1, i)], _col3(scratch, _S_DIR + 3, i)
    stance0 = _stand(c, 0, i, ankles[0], d0, foot0, w[0], sole_roll, footprint, pivot,
                     ankle_height[0], ball, switch, kinds, params, grid, toe_passes, scratch)
    stance1 = _stand(c, 1, i, ankles[1], d1, foot1, w[1], sole_roll, footprint, pivot,
                     ankle_height[1], ball, switch, kinds, params, grid, toe_passes, scratch)
    # The motion's floor follows the ground under the supporting feet, smoothly.
    support = w[0] + w[1]
    under_feet = (w[0] * footprint[c, 0, 2] + w[1] * footprint[c, 1, 2]) / max(support, 1e-9)
    target = under_feet if support > 0.0 else _height(kinds, params, grid, pelvis)
    ground_ref[c] += follow * (target - ground_ref[c])
    g = ground_ref[c]
    # The re-aiming's inputs (the pose decoded before adaptation: decode_lanes's) ...
    scratch[_at(_S_WEIGHT, i)], scratch[_at(_S_WEIGHT + 1, i)] = w[0], w[1]
    scratch[_at(_S_LEG, i)] = leg_c
    scratch[_at(_S_ROOT_HEIGHT, i)] = pelvis[2] + g
    for s in range(2):
        stance = stance0 if s == 0 else stance1
        # Free feet ride on that floor, lifted where heel or toe would go under the ground; a
        # contact ramping in blends towards its planted ankle (its heel kept above the ground
        # by lift_targets, once the ground under it is answered).
        target, under, ask = _foot_target(ankles[s], toes[s], _under_motion(scratch, i, s),
                                          stance[0], stance[2][0], w[s], g, ankle_height[s],
                                          ball)
        _put3(scratch, _S_TARGET + 3 * s, i, target)
        scratch[_at(_S_UNDER + s, i)] = under
        scratch[_at(_S_Q_BLEND + s, i)] = -1.0
        if ask:
            scratch[_at(_S_Q_BLEND + s, i)] = count
            count = _ask(scratch, PITCH_QUERIES + count, target[0], target[1]) - PITCH_QUERIES
        # ... and what the row needs after it: the directions the last pitch starts from (a
        # planted foot's as it stands, its toe end's ground known; a ramping foot's the
        # motion's; a free foot's is found after the re-aiming).
        known = _UNKNOWN
        d = d0 if s == 0 else d1
        if w[s] >= 1.0:
            d = stance[1]
            stood = add_scaled(stance[0], d, foot0 if s == 0 else foot1)
            known = (stood[0], stood[1], stance[2][1])
        _put3(scratch, _S_KNOWN + 3 * s, i, known)
        _put3(scratch, _S_DIR + 3 * s, i, d)
    return count


@jit(inline="always")  # one call site
def lift_targets(i: Column, c: int, lengths: F64, scratch: F64) -> None:
    """Store row ``c``'s ankle targets (column ``i``, :func:`ground_adapt_before`'s) with
    their heels kept above the ground, once :func:`heights_lanes` has answered the blends'
    queries; the ground under them into the column."""
    for s in range(2):
        query = scratch[_at(_S_Q_BLEND + s, i)]
        if query >= 0.0:
            scratch[_at(_S_UNDER + s, i)] = _answer(scratch, PITCH_QUERIES + query)
        target = _lift_target(_col3(scratch, _S_TARGET + 3 * s, i),
                              scratch[_at(_S_UNDER + s, i)], lengths[c, _L_ANKLE_HEIGHT + s])
        _put3(scratch, _S_TARGET + 3 * s, i, target)


@jit(inline="always")  # one call site
def ground_adapt_after(i: Column, c: int, pose: LegPoseArrays, lengths: F64,
                       contact_weight: F64, kinds: I64, params: F64, grid: F64, is_smooth: bool,
                       max_extension: float, heel_tolerance: float, heel_passes: int,
                       scratch: F64, count: int) -> int:
    """Mirrors ``GroundAdapt.run`` for store row ``c`` after the block's re-aiming
    (:func:`reaim_lanes`, column ``i`` of ``scratch``): the heels kept up, the legs' pose
    written, each foot's length and direction the last pitch starts from into the column,
    and the ground under each foot's toe end asked from query ``count`` on (the last pitch's
    first, :func:`pitch_last`) unless known: at most two, under :data:`QUERIES_PER_ROW`;
    returns the queries asked now."""
    ankle_height = (lengths[c, _L_ANKLE_HEIGHT], lengths[c, _L_ANKLE_HEIGHT + 1], 0.0)
    adapt_keeping_heels_up(i, c, pose, scratch, kinds, params, grid, is_smooth, ankle_height,
                           max_extension, heel_tolerance, heel_passes)
    for s in range(2):
        # The direction the foot is pitched from last: a planted foot's as it stands, a
        # ramping one's as the motion has it in the world, a free one's as in its shank.
        if not contact_weight[c, s] > 0.0:
            _put3(scratch, _S_DIR + 3 * s, i, _col3(scratch, _S_AXIS + 3 * s, i))
        end = add_scaled(_col3(scratch, _S_ANKLE + 3 * s, i), _col3(scratch, _S_DIR + 3 * s, i),
                         1.0 * scratch[_at(_S_FOOT_LENGTH + s, i)])
        known = _col3(scratch, _S_KNOWN + 3 * s, i)
        scratch[_at(_S_Q_END + s, i)] = -1.0
        # a planted foot's toe end where it stood is known (as .ground.height_near would take it)
        if not near_known(end[0], end[1], known, is_smooth):
            scratch[_at(_S_Q_END + s, i)] = count
            count = _ask(scratch, count, end[0], end[1])
    return count


@jit(inline="always")  # one call site
def pitch_last(i: Column, c: int, leg: F64, ball_per_leg: float, scratch: F64,
               count: int) -> int:
    """Store row ``c``'s feet (column ``i``) pitched so that their toes are not under the
    ground, once :func:`heights_lanes` has answered the queries of
    :func:`ground_adapt_after`: made entries of :func:`pitch_lanes` from ``count`` on where
    too low (:func:`_to_pitch`); returns the block's entries now."""
    ball = ball_per_leg * leg[c]
    for s in range(2):
        query = scratch[_at(_S_Q_END + s, i)]
        first = _answer(scratch, query) if query >= 0.0 else scratch[_at(_S_KNOWN + 3 * s + 2, i)]
        count = _to_pitch(scratch, count, i, s, _col3(scratch, _S_ANKLE + 3 * s, i),
                          _col3(scratch, _S_DIR + 3 * s, i), scratch[_at(_S_FOOT_LENGTH + s, i)],
                          1.0, ball, first)
    return count


@jit(inline="always")  # one call site
def last_pitch(i: Column, c: int, pose: LegPoseArrays, contact_weight: F64,
               scratch: F64) -> None:
    """Mirrors the end of ``GroundAdapt.run`` for store row ``c`` once :func:`pitch_last` and
    :func:`pitch_lanes` have pitched its feet (column ``i``): each foot's direction written
    (in the shank; a free foot's only where the pitch turned it)."""
    for s in range(2):
        new_d = _col3(scratch, _S_PITCHED + 3 * s, i)
        if contact_weight[c, s] > 0.0 or new_d[2] != scratch[_at(_S_DIR + 3 * s + 2, i)]:
            store3(pose.foot_dir[c, s],
                   in_frame(_col_frame(scratch, _S_SHANK2W + 9 * s, i), new_d))


@jit(nogil=True)
def ground_adapt_rows(lo: int, hi: int, rows: I64, pose: LegPoseArrays, lengths: F64, leg: F64,
                      contact_weight: F64, sole_roll: F64, clip: I64, source_ankle_height: F64,
                      footprint: F64, locked: B1, pivot: I64, ground_ref: F64,
                      ground: GroundArrays, dt: float, smoothing_s: float, ball_per_leg: float,
                      max_extension: float, heel_tolerance: float, switch_per_leg: float,
                      heel_passes: int, toe_passes: int, scratch: F64) -> None:
    """Mirrors ``systems.ground_adapt.GroundAdapt.run`` over the store rows
    ``rows[lo:hi]``, in place.

    Per row: ``pose`` the store's poses' leg arrays (:func:`.decode.leg_pose_arrays`; decoded
    on the body here, then root height, leg frames and fractions, foot directions written);
    ``lengths`` (n, N_LENGTHS) m; ``leg`` (n,) leg lengths m; ``contact_weight`` (n, 2);
    ``sole_roll`` (n, 2) the part of each foot the motion plants (0 heel, 1 ball);
    ``clip`` (n,) int64; ``source_ankle_height`` (n_clips, 2) in leg lengths; ``footprint``
    (n, 2, 3) m, ``locked`` (n, 2) bool, ``pivot`` (n, 2) int64 and ``ground_ref`` (n,) m,
    read and written. ``ground``: (kinds, params, grid) of the ground's description.
    Settings: ``dt`` (s) the tick, ``smoothing_s`` the floor's time constant,
    ``ball_per_leg`` the toe joint's height above the sole per leg length, ``max_extension``
    of a leg, ``heel_tolerance`` (m), ``switch_per_leg`` how near the ground (per leg length)
    a sole point must be for the foot to stand on it, ``heel_passes``, ``toe_passes``.
    ``scratch``: :func:`ground_scratch` of ``len(rows)`` (column ``i`` for ``rows[i]``).

    By blocks of :data:`.lanes.BLOCK` rows: the motion decoded (:func:`decode_lanes`), each
    row's feet laid and the ground asked under them, the block's queries answered at once
    (:func:`heights_lanes`), the feet in contact pitched (:func:`pitch_planted_lanes`, the block's
    at once in :func:`pitch_lanes`), each row up to its legs' re-aiming (the blends' ground
    asked, answered, :func:`lift_targets`), the block's first re-aiming (:func:`reaim_lanes`),
    each row on to the ground under its toes asked, the queries answered, the feet pitched
    (:func:`pitch_last`, :func:`pitch_lanes`) and their directions written; each row's result
    is the same, to the bit, whatever its block.
    """
    kinds, params, grid = ground
    is_smooth = smooth(kinds)
    follow = 1.0 - math.exp(-dt / smoothing_s)
    scratch_block = scratch[lo // BLOCK]
    for start in range(lo, hi, BLOCK):
        stop = min(start + BLOCK, hi)
        for i in range(start, stop):
            gather_motion(Column(i - start), rows[i], pose, lengths, scratch_block)
        n = stop - start
        decode_lanes(scratch_block, Column(0), Column(n))
        count = 0
        for i in range(start, stop):
            count = lay_feet(Column(i - start), rows[i], lengths, leg, contact_weight, sole_roll,
                             clip, source_ankle_height, footprint, locked, pivot, kinds,
                             params, grid, ball_per_leg, scratch_block, count)
        heights_lanes(scratch_block, 0, count, kinds, params, grid)
        pitch_planted_lanes(scratch_block, Column(0), Column(n))
        pitch_lanes(scratch_block, planted_entries(scratch_block, n), kinds, params, grid,
                    toe_passes)
        count = 0
        for i in range(start, stop):
            count = ground_adapt_before(Column(i - start), rows[i], lengths, leg,
                                        contact_weight, sole_roll, footprint, pivot, ground_ref,
                                        kinds, params, grid, follow, ball_per_leg,
                                        switch_per_leg, toe_passes, scratch_block, count)
        heights_lanes(scratch_block, PITCH_QUERIES, PITCH_QUERIES + count, kinds, params, grid)
        for i in range(start, stop):
            lift_targets(Column(i - start), rows[i], lengths, scratch_block)
        reaim_lanes(scratch_block, Column(0), Column(n), max_extension)
        count = 0
        for i in range(start, stop):
            count = ground_adapt_after(Column(i - start), rows[i], pose, lengths,
                                       contact_weight, kinds, params, grid, is_smooth,
                                       max_extension, heel_tolerance, heel_passes,
                                       scratch_block, count)
        heights_lanes(scratch_block, 0, count, kinds, params, grid)
        count = 0
        for i in range(start, stop):
            count = pitch_last(Column(i - start), rows[i], leg, ball_per_leg, scratch_block,
                               count)
        pitch_lanes(scratch_block, count, kinds, params, grid, toe_passes)
        for i in range(start, stop):
            last_pitch(Column(i - start), rows[i], pose, contact_weight, scratch_block)
