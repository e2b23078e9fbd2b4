"""Scalar geometry of the compiled solver's steps, one limb or one point at a time.

Each function mirrors the batched numpy function of :mod:`ecs_anim.solver.steps` (or of
:mod:`ecs_anim.solver.shell`) with the same name, on tuples (3-vectors, frames as their three
axes, :mod:`ecs_anim.runtime.kernels.vec`). Lengths in metres, angles in radians.

The generic rotations they build on (``axis_angle``, ``rotation_about``, ``rotation_toward``,
``axis_angle_of``) are in :mod:`ecs_anim.runtime.kernels.vec`.
"""

from __future__ import annotations

import math

from ecs_anim.runtime.kernels.vec import (
    Frame,
    Vec3,
    add,
    add_scaled,
    cross,
    dot,
    frame_from_axes,
    jit,
    norm,
    normalize,
    rotation_about,
    rotation_toward,
    scale,
    sub,
    to_world,
)


@jit()
def bring_within_reach(base: Vec3, limb_root: Vec3, goal: Vec3, reach: float,
                       max_angle: float) -> Frame:
    """Mirrors :func:`ecs_anim.solver.steps.bring_within_reach`: the smallest rotation about
    ``base``
    bringing ``limb_root`` within ``reach`` of ``goal``, at most ``max_angle``."""
    a_vec, b_vec = sub(limb_root, base), sub(goal, base)
    a = norm(a_vec)
    b = norm(b_vec)
    angle_now = math.acos(min(max(dot(a_vec, b_vec) / max(a * b, 1e-12), -1.0), 1.0))
    cos_enough = (a**2 + b**2 - reach**2) / max(2.0 * a * b, 1e-12)
    angle_enough = math.acos(min(max(cos_enough, -1.0), 1.0))
    turn = min(max(angle_now - angle_enough, 0.0), max_angle)
    weight = turn / max(angle_now, 1e-12) if angle_now > 1e-12 else 0.0
    return rotation_toward(a_vec, b_vec, math.pi, weight)


@jit()
def flexion(fraction: float, upper: float, lower: float) -> float:
    """Mirrors :func:`ecs_anim.solver.steps.flexion`: middle-joint flexion (0 = straight)."""
    span = fraction * (upper + lower)
    return math.acos(min(max((span**2 - upper**2 - lower**2) / (2 * upper * lower), -1.0), 1.0))


@jit()
def point_in_limb(upper: float, lower: float, fraction: float, on_lower: bool, q: Vec3) -> Vec3:
    """Mirrors :func:`ecs_anim.solver.steps.point_in_limb`: a limb point (bone coordinates ``q``) in
    the half-plane frame, the root at the origin."""
    span = min(max(fraction * (upper + lower), abs(upper - lower) + 1e-9), upper + lower)
    z_e = (upper**2 - lower**2 + span**2) / (2.0 * span)
    y_e = math.sqrt(max(upper**2 - z_e**2, 0.0))
    if on_lower:
        d = (0.0 / lower, -y_e / lower, (span - z_e) / lower)
        origin = (0.0, y_e, z_e)
    else:
        d = (0.0 / upper, y_e / upper, z_e / upper)
        origin = (0.0, 0.0, 0.0)
    y_axis = (0.0, d[2], -d[1])
    out = add(origin, (q[0] * 1.0, q[0] * 0.0, q[0] * 0.0))
    out = add(out, scale(y_axis, q[1]))
    return add(out, scale(d, q[2]))


@jit()
def wrap_angle(angle: float) -> float:
    """``(angle + pi) % (2 pi) - pi`` to the bit (Python's and numpy's float modulo), without
    the modulo's call (a tenth of the solve's time) where it is one exact step: for
    ``x = angle + pi`` in ``[0, 4 pi)``, ``fmod`` is ``x`` or ``x - 2 pi`` (exact: Sterbenz), and
    in ``(-2 pi, 0)`` the modulo is ``fmod``'s ``x`` plus 2 pi, the same addition."""
    two_pi = 2 * math.pi
    x = angle + math.pi
    if 0.0 <= x < two_pi:
        wrapped = x
    elif two_pi <= x < 2.0 * two_pi:
        wrapped = x - two_pi
    elif -two_pi < x < 0.0:
        wrapped = x + two_pi
    else:
        wrapped = x % two_pi
    return wrapped - math.pi


@jit()
def reach_point(root: Vec3, limb2world: Frame, upper: float, lower: float, fraction: float,
                on_lower: bool, q: Vec3, goal: Vec3,
                max_extension: float) -> tuple[Frame, float, Vec3]:
    """Mirrors :func:`ecs_anim.solver.steps.reach_point`: bring the limb point ``q`` onto ``goal``
    (flexion first, the nearest to the current one, then the smallest turn about the root).
    Returns (limb2world, fraction, the point's new position)."""
    uu, ll = upper, lower
    phi_now = flexion(fraction, uu, ll)
    distance = norm(sub(goal, root))
    wanted = (distance**2 - uu**2 - dot(q, q)) / (2.0 * uu)
    r = math.hypot(q[1], q[2])
    delta = math.atan2(q[1], q[2])
    phi_lo = flexion(max_extension, uu, ll)
    phi_hi = math.pi - 1e-3
    spread = math.acos(min(max(wanted / max(r, 1e-12), -1.0), 1.0))
    candidates = (delta + spread, delta - spread, delta, delta + math.pi, phi_lo, phi_hi, phi_now)
    phi = phi_now
    best = math.inf
    for k in range(7):
        candidate = min(max(wrap_angle(candidates[k]), phi_lo), phi_hi)
        # A candidate whose tie-break term alone is no less than the best miss cannot be
        # strictly below it (the other term is not negative): its cosine is not needed.
        tie_break = 1e-9 * abs(candidate - phi_now)
        if tie_break >= best:
            continue
        miss = abs(r * math.cos(candidate - delta) - wanted) + tie_break
        if miss < best:
            best, phi = miss, candidate
    new_fraction = fraction
    if on_lower:
        span = math.sqrt(max(uu**2 + ll**2 + 2 * uu * ll * math.cos(phi), 0.0))
        new_fraction = span / (uu + ll)
    local = point_in_limb(uu, ll, new_fraction, on_lower, q)
    now = to_world(limb2world, local)
    turn = rotation_toward(now, sub(goal, root), math.pi, 1.0)
    frame = (to_world(turn, limb2world[0]), to_world(turn, limb2world[1]),
             to_world(turn, limb2world[2]))
    return frame, new_fraction, add(root, to_world(frame, local))


@jit()
def reach_end_applies(upper: float, lower: float, distance: float, along_axis: float,
                      max_extension: float) -> bool:
    """Whether :func:`reach_end` gives :func:`reach_point`'s limb for a goal ``distance`` (m)
    from the root, ``along_axis`` (m) of it along the limb's axis: both bones have a length, the
    span (the distance, or ``max_extension`` of the limb beyond it) is farther than the folded
    limb reaches by a thousandth of the limb (nearer, ``reach_point`` folds it at its least
    flexion) and nearer than the straight limb by a millionth (there the arc cosine's rounding
    is 2e-9 m at an elbow), and the goal does not lie behind the limb's axis. False for any
    NaN."""
    limb = upper + lower
    span = min(distance, max_extension * limb)
    return (upper > 0.0 and lower > 0.0 and span > abs(upper - lower) + 1e-3 * limb
            and span <= (1.0 - 1e-6) * limb and along_axis > -0.5 * distance)


# Inlined by numba: a call left in the loop of :func:`.solve_limbs.arm_lanes` would keep LLVM
# from vectorizing it.
@jit(inline="always")
def reach_end(root: Vec3, limb2world: Frame, upper: float, lower: float, to_goal: Vec3,
              distance: float, max_extension: float) -> tuple[Frame, float, Vec3]:
    """:func:`reach_point` for the limb's end (bone coordinates ``(0, 0, lower)`` on the lower
    bone: an ankle, a wrist) onto a goal ``to_goal`` from the root, ``distance`` (m) away, no
    nearer than the folded limb reaches (``|upper - lower|`` plus a thousandth of the limb: then
    the flexion :func:`reach_point` picks is the one spanning ``distance``, or the straightest
    allowed, ``max_extension`` of the limb, beyond it), where the goal does not lie behind the
    limb's axis. The same limb to rounding (1e-15 m), without its trigonometry: the span is the
    distance itself (``reach_point`` takes an arc cosine, then the cosine of its result), the
    turn the smallest rotation of the limb's axis (its z, on which the end lies) onto the goal,
    by Rodrigues' formula (``reach_point`` an arc tangent, then its sine and cosine).
    Returns (limb2world, fraction, the end's new position)."""
    span = min(distance, max_extension * (upper + lower))
    # Each axis v turned by Rodrigues' formula with k = z x goal (|k| the sine, c the cosine):
    # v c + k x v + k (k . v) / (1 + c); c > -1/2 where it is taken.
    goal_dir = scale(to_goal, 1.0 / distance)
    k = cross(limb2world[2], goal_dir)
    c = dot(limb2world[2], goal_dir)
    d = 1.0 / (1.0 + c)
    x = add(add(scale(limb2world[0], c), cross(k, limb2world[0])),
            scale(k, dot(k, limb2world[0]) * d))
    y = add(add(scale(limb2world[1], c), cross(k, limb2world[1])),
            scale(k, dot(k, limb2world[1]) * d))
    z = add(add(scale(limb2world[2], c), cross(k, limb2world[2])),
            scale(k, dot(k, limb2world[2]) * d))
    return (x, y, z), span / (upper + lower), add(root, scale(z, span))


@jit()
def turn_about_axis(root: Vec3, axis_through: Vec3, point: Vec3, goal: Vec3) -> Frame:
    """Mirrors :func:`ecs_anim.solver.steps.turn_about_axis`: the rotation about root ->
    ``axis_through`` bringing ``point`` closest to ``goal`` (the identity on the axis). The
    angle's sine and cosine are taken from the two projections themselves (``atan2``, then
    ``sin`` and ``cos`` of its result there: the same to rounding). A call, where the loops
    over a block inline :func:`turn_about_axis_lanes` itself."""
    return turn_about_axis_lanes(root, axis_through, point, goal)


# Branch-free forms for the loops over a block's characters (:func:`.solve_limbs.arm_lanes`):
# every case computed, then chosen by selects, with the same operations in the same order as
# point_in_limb's, so the same bits; turn_about_axis is its own.


@jit(inline="always")
def point_in_limb_lanes(upper: float, lower: float, fraction: float, on_lower: bool,
                        q: Vec3) -> Vec3:
    """:func:`point_in_limb` (the same bits) without branches: the bone's length, direction
    and origin chosen by ``on_lower``."""
    span = min(max(fraction * (upper + lower), abs(upper - lower) + 1e-9), upper + lower)
    z_e = (upper**2 - lower**2 + span**2) / (2.0 * span)
    y_e = math.sqrt(max(upper**2 - z_e**2, 0.0))
    length = lower if on_lower else upper
    d = (0.0 / length, (-y_e if on_lower else y_e) / length,
         ((span - z_e) if on_lower else z_e) / length)
    origin = (0.0, y_e if on_lower else 0.0, z_e if on_lower else 0.0)
    y_axis = (0.0, d[2], -d[1])
    out = add(origin, (q[0] * 1.0, q[0] * 0.0, q[0] * 0.0))
    out = add(out, scale(y_axis, q[1]))
    return add(out, scale(d, q[2]))


@jit(inline="always")
def turn_about_axis_lanes(root: Vec3, axis_through: Vec3, point: Vec3, goal: Vec3) -> Frame:
    """:func:`turn_about_axis` (the same bits) without branches: the identity's sine and
    cosine (0, 1) chosen where the point or the goal lies on the axis."""
    k = normalize(sub(axis_through, root))
    v, t = sub(point, root), sub(goal, root)
    v = add_scaled(v, k, -dot(v, k))
    t = add_scaled(t, k, -dot(t, k))
    y, x = dot(k, cross(v, t)), dot(v, t)
    h = math.sqrt(x * x + y * y)
    turns = (norm(v) > 1e-9) & (norm(t) > 1e-9) & (h > 0.0)
    return rotation_about(k, y / h if turns else 0.0, x / h if turns else 1.0)


@jit()
def distal_in_lower(direction: Vec3) -> Frame:
    """Mirrors ``solver_shell._distal_in_lower``: a foot / hand frame in its lower bone's frame
    (z along ``direction``, x the limb normal)."""
    return frame_from_axes(direction, (1.0, 0.0, 0.0), 2, 0, (0.0, 1.0, 0.0))


@jit()
def bone_coords(bone: int, fraction: float, offset: Vec3, upper: float, lower: float,
                distal: float, distal_dir: Vec3) -> tuple[Vec3, bool]:
    """Mirrors ``solver_shell._bone_coords`` for one point: its coordinates in its bone's frame
    (a foot / hand point in the lower bone's, through ``distal_dir``) and whether it moves with
    the lower bone. ``bone`` 0 upper, 1 lower, 2 distal."""
    length = upper if bone == 0 else (lower if bone == 1 else distal)
    q = (offset[0], offset[1], offset[2] + fraction * length)
    if bone == 2:
        q = to_world(distal_in_lower(distal_dir), q)
        q = (q[0], q[1], q[2] + lower)
    return q, bone >= 1
