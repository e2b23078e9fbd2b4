"""Compiled ground adaptation (paper §7): the whole of ``GroundAdapt.run``, one character at a time.

Mirrors ``systems.ground_adapt.GroundAdapt.run`` (footprints laid on the sole point each foot
stands on and moved as the foot rolls, the motion's floor following the supporting feet, free
feet lifted clear of the ground, the toes pitched onto it) with :func:`ecs_anim.core.ground_adapt.adapt_keeping_heels_up`,
:func:`~ecs_anim.core.ground_adapt.adapt_to_ground` and
:func:`~ecs_anim.core.ground_adapt.vertical_slack_for_reach`, on a built-in ground given as its
:class:`~ecs_anim.core.ground.GroundDescription` arrays.

Every decision the numpy code takes for the whole batch (another heel pass, the toe passes) is
taken here per character, so a character's result never depends on who else is in the batch.

Length indices are literals (numba's cache keys on this file's source); an import-time
check pins them to the skeleton.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core import ground_adapt as reference
from ecs_anim.core.skeleton import LENGTH_INDEX as L
from ecs_anim.runtime.kernels.decode import LegPoseArrays, decode_legs_row, leg_below_hip
from ecs_anim.runtime.kernels.ground import height_at, height_near, smooth
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
    norm,
    quat_from_matrix,
    rotation_between,
    scale,
    store3,
    store4,
    sub,
    transpose,
)

I64 = NDArray[np.int64]
B1 = NDArray[np.bool_]
#: A ground's description: (kinds, params, grid) of :class:`ecs_anim.core.ground.GroundDescription`.
GroundArrays = tuple[I64, F64, F64]

# Lengths of side s (0 left, 1 right) are these plus s.
_L_THIGH, _L_SHANK, _L_ANKLE_HEIGHT = 2, 4, 8
assert (L["thigh_l"], L["shank_l"], L["ankle_height_l"], L["thigh_r"], L["ankle_height_r"]) \
    == (_L_THIGH, _L_SHANK, _L_ANKLE_HEIGHT, _L_THIGH + 1, _L_ANKLE_HEIGHT + 1)
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


@jit(inline="always")
def adapt_to_ground(c: int, root_position: F64, leg_frame: F64, leg_fraction: F64,
                    hips: tuple[Vec3, Vec3], pelvis_now: Vec3, pelvis2world: Frame,
                    leg2world: tuple[Frame, Frame], lengths: F64, leg: float,
                    targets: tuple[Vec3, Vec3], weights: tuple[float, float],
                    root_height: float, max_extension: float
                    ) -> tuple[tuple[Vec3, Vec3], tuple[Frame, Frame]]:
    """Mirrors :func:`ecs_anim.core.ground_adapt.adapt_to_ground` for store row ``c`` (legs
    re-aimed from the pose decoded before adaptation: its ``hips``, ``pelvis2world`` and
    ``leg2world``; the pelvis lowered as the legs in contact need, moved horizontally where a
    leg cannot reach by that), writing the root
    position, leg frames and fractions of row ``c`` of the poses (``root_position``,
    ``leg_frame``, ``leg_fraction``). ``pelvis_now`` (m, world): the pelvis before adaptation.
    Returns the new hips (m, world) and leg2world (what decoding the row would give, within
    rounding: the rest of the legs is decoded from them, :func:`.decode.leg_below_hip`).

    ``targets``: each ankle's target (m, world); ``weights``: contact activations;
    ``root_height`` (m): the pelvis height the motion wants; ``leg``: the leg length (m).
    """
    up = root_height - pelvis_now[2]
    shift_x, shift_y = 0.0, 0.0
    for s in range(2):
        hip = hips[s]
        reach = max_extension * (lengths[c, _L_THIGH + s] + lengths[c, _L_SHANK + s])
        w = min(max(weights[s], 0.0), 1.0)
        ex, ey = horizontal_reach_excess((hip[0] + 0.0, hip[1] + 0.0, hip[2] + up), targets[s],
                                         reach)
        shift_x += w * ex
        shift_y += w * ey
    lowest = 0.0
    for s in range(2):
        hip = hips[s]
        reach = max_extension * (lengths[c, _L_THIGH + s] + lengths[c, _L_SHANK + s])
        needed = vertical_slack_for_reach((hip[0] + shift_x, hip[1] + shift_y, hip[2] + up),
                                          targets[s], reach)
        w = min(max(weights[s], 0.0), 1.0)
        drop = w * min(needed, 0.0)
        lowest = drop if s == 0 else min(lowest, drop)
    pelvis_z = root_height + lowest
    shift = pelvis_z - pelvis_now[2]
    world2pelvis = transpose(pelvis2world)
    new_hips = (add(hips[0], (shift_x, shift_y, shift)), add(hips[1], (shift_x, shift_y, shift)))
    new_leg2world = (leg2world[0], leg2world[1])
    for s in range(2):
        thigh, shank = lengths[c, _L_THIGH + s], lengths[c, _L_SHANK + s]
        reach = max_extension * (thigh + shank)
        to_target = sub(targets[s], new_hips[s])
        turned = matmul(rotation_between(leg2world[s][2], to_target), leg2world[s])
        store4(leg_frame[c, s], quat_from_matrix(matmul(world2pelvis, turned)))
        leg_fraction[c, s] = min(norm(to_target), reach) / (thigh + shank)
        new_leg2world = (turned, new_leg2world[1]) if s == 0 else (new_leg2world[0], turned)
    root_position[c, 0] = (pelvis_now[0] + shift_x) / leg
    root_position[c, 1] = (pelvis_now[1] + shift_y) / leg
    root_position[c, 2] = pelvis_z / leg
    return new_hips, new_leg2world


@jit(inline="always")  # one call site
def adapt_keeping_heels_up(c: int, pose: LegPoseArrays, hips: tuple[Vec3, Vec3],
                           pelvis_now: Vec3, pelvis2world: Frame,
                           leg2world: tuple[Frame, Frame], lengths: F64, leg: float,
                           targets: tuple[Vec3, Vec3], under_targets: tuple[float, float],
                           weights: tuple[float, float], root_height: float, kinds: I64,
                           params: F64, grid: F64, is_smooth: bool, ankle_height: Vec3,
                           max_extension: float, heel_tolerance: float, passes: int
                           ) -> tuple[tuple[Vec3, Vec3], tuple[Vec3, Vec3], tuple[Frame, Frame]]:
    """Mirrors :func:`ecs_anim.core.ground_adapt.adapt_keeping_heels_up` for store row ``c``: the
    ankle targets lifted (up to ``passes`` times) while a heel would be more than
    ``heel_tolerance`` (m) under the ground. ``under_targets``: the ground's height under each
    target (m; lifting a target keeps its x, y): an ankle that reached its target is not asked
    about again on a smooth ground (``is_smooth``, :func:`.ground.height_near`).
    ``ankle_height`` (left, right, unused) m;
    ``hips``, ``pelvis_now``, ``pelvis2world``, ``leg2world``: the pose decoded before
    adaptation, as :func:`adapt_to_ground` takes them.

    Writes row ``c`` of ``pose`` as :func:`adapt_to_ground`; returns the decoded (ankles, toes,
    shank2world) of the result (decoded from the hips and leg frames the adaptation gives, as
    :func:`.decode.decode_legs_row` would within rounding, without decoding the pelvis again).
    """
    root_position, leg_frame, leg_fraction = pose.root_position, pose.leg_frame, pose.leg_fraction
    lengths_row = lengths[c]
    # One call site each for the two inlined steps (numba compiles an inlined body at each):
    # the first pass adapts to the targets given, the next ones to the lifted targets.
    for lift in range(passes + 1):
        new_hips, new_leg2world = adapt_to_ground(
            c, root_position, leg_frame, leg_fraction, hips, pelvis_now, pelvis2world,
            leg2world, lengths, leg, targets, weights, root_height, max_extension)
        _, ankle0, toe0, shank0 = leg_below_hip(c, 0, pose, lengths_row, new_hips[0],
                                                new_leg2world[0])
        _, ankle1, toe1, shank1 = leg_below_hip(c, 1, pose, lengths_row, new_hips[1],
                                                new_leg2world[1])
        ankles, toes, shank2world = (ankle0, ankle1), (toe0, toe1), (shank0, shank1)
        if lift == passes:
            break
        t0, t1 = targets
        d0 = height_near(ankles[0][0], ankles[0][1], (t0[0], t0[1], under_targets[0]), is_smooth,
                         kinds, params, grid) + ankle_height[0] - ankles[0][2]
        d1 = height_near(ankles[1][0], ankles[1][1], (t1[0], t1[1], under_targets[1]), is_smooth,
                         kinds, params, grid) + ankle_height[1] - ankles[1][2]
        if not (d0 > heel_tolerance or d1 > heel_tolerance):
            break
        targets = ((t0[0], t0[1], t0[2] + max(d0, 0.0)), (t1[0], t1[1], t1[2] + max(d1, 0.0)))
    return ankles, toes, shank2world


# Not inlined (nor planted_foot): a row calls them from nine places, and inlining each copy
# tripled ground_adapt_rows's compile time (14 s of CPU, 43 s inlined) for 1-5 % of its run.
@jit()
def pitched(origin: Vec3, d: Vec3, foot: float, sign: float, clearance: float, kinds: I64,
            params: F64, grid: F64, passes: int, known: Vec3, is_smooth: bool
            ) -> tuple[Vec3, float]:
    """Mirrors :func:`ecs_anim.core.ground_adapt.pitched`: the foot direction ``d`` (unit, world)
    turned in its vertical plane, at most ``passes`` times asking the ground again, until the
    foot's other end ``origin + sign * foot * d`` is ``clearance`` (m) above the ground or
    less than :data:`~ecs_anim.core.ground_adapt.TOE_TOLERANCE_M` under that; ``sign`` +1
    about the ankle (the toe end lifted), -1 about the ball (the ankle end). Each pass is a
    secant step (:func:`~ecs_anim.core.ground_adapt.pitch_slope`).
    Returns (that direction, the ground's height under the other end it puts the foot's at, m:
    asked once here, so the caller need not ask again). ``known`` (x, y, height; NaN: none):
    a point whose height is known, taken for the first end if that is within
    :data:`.ground.NEAR_M` of it on a smooth ground (``is_smooth``)."""
    dz = d[2]
    end = add_scaled(origin, d, sign * foot)
    ground = height_near(end[0], end[1], known, is_smooth, kinds, params, grid)
    deficit = ground + clearance - end[2]
    last_dz, last_deficit = dz, deficit
    hx, hy = 0.0, 0.0  # the horizontal heading, once a pass needs it (most feet need none)
    for turn in range(passes):
        if not deficit > TOE_TOLERANCE_M:
            break
        if turn == 0:
            flat = max(math.sqrt(d[0] * d[0] + d[1] * d[1]), 1e-9)
            hx, hy = d[0] / flat, d[1] / flat
        slope = pitch_slope(dz, deficit, last_dz, last_deficit, sign * foot)
        last_dz, last_deficit = dz, deficit
        dz = min(max(dz - deficit / slope, -1.0), 1.0)
        along = math.sqrt(1.0 - dz * dz)
        d = (hx * along, hy * along, dz)
        end = add_scaled(origin, d, sign * foot)
        ground = height_at(end[0], end[1], kinds, params, grid)
        deficit = ground + clearance - end[2]
    return d, ground


@jit(inline="always")
def pitch_slope(dz: float, deficit: float, last_dz: float, last_deficit: float,
                rise: float) -> float:
    """Mirrors :func:`ecs_anim.core.ground_adapt.pitch_slope` for one foot (m of deficit per
    unit of the direction's z)."""
    flat = -rise
    step = dz - last_dz
    if step == 0.0:
        return flat
    secant = (deficit - last_deficit) / step
    ratio = secant / flat
    return secant if MIN_SECANT_RATIO < ratio < MAX_SECANT_RATIO else flat


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
        d, under_toe = pitched(ankle, d, foot, 1.0, ball, kinds, params, grid, passes, _UNKNOWN,
                               False)
        return ankle, d, (sole_point[2], under_toe)
    toe = (sole_point[0], sole_point[1], sole_point[2] + ball)
    d, under_ankle = pitched(toe, d, foot, -1.0, ankle_height, kinds, params, grid, passes,
                             _UNKNOWN, False)
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
def _foot_target(ankle: Vec3, toe: Vec3, planted_ankle: Vec3, under_planted: float, w: float,
                 ground_ref: float, ankle_height: float, ball: float, kinds: I64, params: F64,
                 grid: F64) -> tuple[Vec3, float]:
    """One ankle's target in ``GroundAdapt.run`` and the ground's height under it (m): the motion's free foot on the floor
    ``ground_ref`` (m), lifted where its heel or toe would be under the ground, blended
    towards where the planted foot puts it (``planted_ankle``, the ground ``under_planted``
    it, m) by the contact weight ``w``, its heel kept above the ground.

    The ground is asked only where nobody has: a planted foot's target is its ankle (two
    queries fewer: where the free foot would be does not count), a free foot's is where the
    heel was asked about."""
    if w == 1.0:
        t, under = planted_ankle, under_planted
    else:
        free = (ankle[0], ankle[1], ankle[2] + ground_ref)
        under_free = _height(kinds, params, grid, free)
        need_heel = under_free + ankle_height - free[2]
        need_toe = _height(kinds, params, grid, toe) + ball - (toe[2] + ground_ref)
        free = (free[0], free[1], free[2] + max(0.0, max(need_heel, need_toe)))
        t = (free[0] + w * (planted_ankle[0] - free[0]),
             free[1] + w * (planted_ankle[1] - free[1]),
             free[2] + w * (planted_ankle[2] - free[2]))
        # (w == 0 leaves the point where it was asked about: (x + 0 * ...) is x)
        under = under_free if w == 0.0 else _height(kinds, params, grid, t)
    return (t[0], t[1], t[2] + max(under + ankle_height - t[2], 0.0)), under


@jit(inline="always")
def _stand(c: int, s: int, ankle: Vec3, toe: Vec3, foot: float, d: Vec3, w: float,
           sole_roll: F64, clip: I64, source_ankle_height: F64, footprint: F64, locked: B1,
           pivot: I64, leg: float, ankle_height: float, ball: float, switch: float,
           kinds: I64, params: F64, grid: F64, passes: int
           ) -> tuple[Vec3, Vec3, tuple[float, float]]:
    """Foot ``s`` of row ``c`` in ``GroundAdapt.run``: its footprint laid, kept or moved
    onto the other sole point, and (ankle, foot direction, the ground's heights under that
    ankle and under the toe end (m), as :func:`planted_foot`) standing on it; the motion's
    (``ankle``, ``d``, NaN: not asked) for a foot not in contact. ``foot`` (m), ``d`` (unit):
    the motion's ankle-to-toe length and direction (:func:`_foot_axis`).

    A contact's footprint is laid where the motion puts its planted point (the heel, the ball,
    or the lower of the two where the motion plants both), on the ground under it; it moves to
    the other point only once the foot has rolled onto it (within ``switch`` m of the ground),
    so the foot turns about the point it stands on and never jumps."""
    if not w > 0.0:
        locked[c, s] = False
        return ankle, d, (math.nan, math.nan)
    if not locked[c, s]:
        heel_up = ankle[2] - source_ankle_height[clip[c], s] * leg
        pivot[c, s] = _pivot_wanted(sole_roll[c, s], 0 if heel_up <= toe[2] - ball else 1)
        point = ankle if pivot[c, s] == 0 else toe
        store3(footprint[c, s], (point[0], point[1], _height(kinds, params, grid, point)))
        locked[c, s] = True
    a, d, under = planted_foot(pivot[c, s], load3(footprint[c, s]), d, foot, ankle_height,
                               ball, kinds, params, grid, passes)
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


@jit(inline="always")  # one call site: a call per row, handed its arrays, costs
def ground_adapt_row(c: int, pose: LegPoseArrays, lengths: F64, leg: F64,
                     contact_weight: F64, sole_roll: F64, clip: I64, source_ankle_height: F64,
                     footprint: F64, locked: B1, pivot: I64, ground_ref: F64, kinds: I64,
                     params: F64, grid: F64, is_smooth: bool, follow: float,
                     ball_per_leg: float, max_extension: float, heel_tolerance: float,
                     switch_per_leg: float, heel_passes: int, toe_passes: int) -> None:
    """Mirrors ``GroundAdapt.run`` for store row ``c``; arguments as for
    :func:`ground_adapt_rows` (``kinds``, ``params``, ``grid``: the arrays of ``ground``;
    ``is_smooth``: :func:`.ground.smooth` of it; ``follow``: the share of the way to the ground
    under the feet the floor moves this tick, the same for every row)."""
    # The pose on the character's body as the motion gives it (MorphologyAdapt's scaling,
    # decoded here: ground adaptation reads only the pelvis and legs).
    lengths_row = lengths[c]
    pelvis, pelvis2world, hips, _, ankles, toes, leg2world, _ = decode_legs_row(
        c, pose, lengths_row, lengths_row)
    leg_c = leg[c]
    ball = ball_per_leg * leg_c
    switch = switch_per_leg * leg_c
    ankle_height = (lengths[c, _L_ANKLE_HEIGHT], lengths[c, _L_ANKLE_HEIGHT + 1], 0.0)
    w = (contact_weight[c, 0], contact_weight[c, 1])
    # Each foot in contact stands on one sole point (its footprint, on the ground): the heel
    # or the ball, as the motion plants it.
    foot0, d0 = _foot_axis(ankles[0], toes[0])
    foot1, d1 = _foot_axis(ankles[1], toes[1])
    stance0 = _stand(c, 0, ankles[0], toes[0], foot0, d0, w[0], sole_roll, clip,
                     source_ankle_height, footprint, locked, pivot, leg_c, ankle_height[0],
                     ball, switch, kinds, params, grid, toe_passes)
    stance1 = _stand(c, 1, ankles[1], toes[1], foot1, d1, w[1], sole_roll, clip,
                     source_ankle_height, footprint, locked, pivot, leg_c, ankle_height[1],
                     ball, switch, kinds, params, grid, toe_passes)
    # The motion's floor follows the ground under the supporting feet, smoothly.
    support = w[0] + w[1]
    under_feet = (w[0] * footprint[c, 0, 2] + w[1] * footprint[c, 1, 2]) / max(support, 1e-9)
    target = under_feet if support > 0.0 else _height(kinds, params, grid, pelvis)
    ground_ref[c] += follow * (target - ground_ref[c])
    g = ground_ref[c]
    # Free feet ride on that floor, lifted where heel or toe would go under the ground; a
    # contact ramping in blends towards its planted ankle, its heel kept above the ground.
    target0, under0 = _foot_target(ankles[0], toes[0], stance0[0], stance0[2][0], w[0], g,
                                   ankle_height[0], ball, kinds, params, grid)
    target1, under1 = _foot_target(ankles[1], toes[1], stance1[0], stance1[2][0], w[1], g,
                                   ankle_height[1], ball, kinds, params, grid)
    root_height = pelvis[2] + g
    new_ankles, new_toes, shank2world = adapt_keeping_heels_up(
        c, pose, hips, pelvis, pelvis2world, leg2world, lengths, leg_c, (target0, target1),
        (under0, under1), w, root_height, kinds, params, grid, is_smooth, ankle_height,
        max_extension, heel_tolerance, heel_passes)
    # Feet: a planted one pitched as it stands (in the world, whatever the leg's new bend), a
    # ramping one as the motion has it in the world, a free one as in its shank; none with
    # its toe under the ground. A planted foot whose ankle reached its footing has its toe
    # end where it stood, whose ground is known.
    for s in range(2):
        ankle, toe = new_ankles[s], new_toes[s]
        foot = max(norm(sub(toe, ankle)), 1e-9)
        known = _UNKNOWN
        if w[s] >= 1.0:
            stance = stance0 if s == 0 else stance1
            d = stance[1]
            stood = add_scaled(stance[0], d, foot0 if s == 0 else foot1)
            known = (stood[0], stood[1], stance[2][1])
        elif w[s] > 0.0:
            d = d0 if s == 0 else d1
        else:
            d = scale(sub(toe, ankle), 1.0 / foot)
        new_d = pitched(ankle, d, foot, 1.0, ball, kinds, params, grid, toe_passes, known,
                        is_smooth)[0]
        if w[s] > 0.0 or new_d[2] != d[2]:
            store3(pose.foot_dir[c, s], in_frame(shank2world[s], new_d))


@jit(nogil=True)
def ground_adapt_rows(lo: int, hi: int, rows: I64, pose: LegPoseArrays, lengths: F64, leg: F64,
                      contact_weight: F64, sole_roll: F64, clip: I64, source_ankle_height: F64,
                      footprint: F64, locked: B1, pivot: I64, ground_ref: F64,
                      ground: GroundArrays, dt: float, smoothing_s: float, ball_per_leg: float,
                      max_extension: float, heel_tolerance: float, switch_per_leg: float,
                      heel_passes: int, toe_passes: int) -> None:
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
    """
    kinds, params, grid = ground
    is_smooth = smooth(kinds)
    follow = 1.0 - math.exp(-dt / smoothing_s)
    for i in range(lo, hi):
        ground_adapt_row(rows[i], pose, lengths, leg, contact_weight, sole_roll, clip,
                         source_ankle_height, footprint, locked, pivot, ground_ref, kinds,
                         params, grid, is_smooth, follow, ball_per_leg, max_extension,
                         heel_tolerance, switch_per_leg, heel_passes, toe_passes)
