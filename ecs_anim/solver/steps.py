"""Constraint-solver steps on limbs of variable length (paper §9, fig. 11), as pure batched kernels.

A limb (arm or leg) is its root joint, its half-plane frame (``z`` root -> end, ``y`` towards the
middle joint) and its length fraction. The steps here return a new frame and fraction; the
solver shell (the constraint issue's ConstraintSolve) owns priorities, iterations and blending.

* :func:`reach_point` — the analytic step: put any point of the limb (its end, mid-forearm, a
  point on the shank) on a goal; out of reach, as near as the limb allows (the error is then the
  geometric minimum).
* :func:`middle_after_root_move` — where a limb's middle joint goes when its root moves and its end
  stays (the root step's prediction of the pass after it).
* :func:`turn_about_axis` — a lower-priority step: turn about the line through a
  higher-priority point (which stays exactly where it is) to bring another point as close as
  possible to its goal: the best point on the circle of solutions (fig. 11 b).

Shapes: ``(n, 3)`` points, ``(n, 3, 3)`` frames (axes as columns), ``(n,)`` lengths in metres.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.normalized import two_sphere_middle
from ecs_anim.core.rotations import axis_angle, normalize

F64 = NDArray[np.float64]


# --- Points anywhere on a limb (mid-forearm, the hand, a point on the shank) -------------------
#
# A limb's shape has one degree of freedom, the middle joint's flexion ``phi`` (0 = straight):
# the root-end span is ``s² = u² + l² + 2 u l cos(phi)``, and a point given in the lower bone's
# frame (``q``: x the limb normal, z along the bone) lies at
# ``|P - root|² = u² + |q|² + 2 u (q_z cos(phi) + q_y sin(phi))`` from the root. So the flexion
# that puts the point at the target's distance is analytic; a rotation about the root then aims
# it (paper §9's analytic limbs, generalised from the end to any point of the limb).

def rotation_toward(a: F64, b: F64, max_angle: float | F64 = np.pi, weight: F64 | float = 1.0) -> F64:
    """The smallest rotation taking direction ``a`` toward ``b`` (..., 3), by ``weight`` of the
    way and at most ``max_angle`` radians. Zero vectors give the identity. (..., 3, 3)."""
    axis = np.cross(a, b)
    sin_ab = np.linalg.norm(axis, axis=-1)
    angle = np.arctan2(sin_ab, np.sum(a * b, axis=-1))
    # Opposite directions: any perpendicular axis.
    helper = np.where(np.abs(a[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    axis = np.where((sin_ab < 1e-12)[..., None], np.cross(a, helper), axis)
    angle = np.minimum(angle * weight, max_angle)
    degenerate = (np.linalg.norm(a, axis=-1) < 1e-12) | (np.linalg.norm(b, axis=-1) < 1e-12)
    return axis_angle(normalize(axis), np.where(degenerate, 0.0, angle))


def bring_within_reach(base: F64, limb_root: F64, goal: F64, reach: F64,
                       max_angle: float | F64 = np.pi) -> F64:
    """The smallest rotation about ``base`` (the pelvis) that brings ``limb_root`` (a shoulder,
    the neck) within ``reach`` (n,) metres of ``goal``, at most ``max_angle`` radians; where no
    turn does, the one that brings it nearest (``base -> limb_root`` turned onto ``base ->
    goal``). Points (n, 3); returns (n, 3, 3). A limb that cannot reach its goal needs its root
    moved toward it, not its end turned about the pelvis: the second stalls once the limb is
    straight, short of a goal the straightened trunk and limb together reach."""
    a_vec, b_vec = limb_root - base, goal - base
    a = np.linalg.norm(a_vec, axis=-1)
    b = np.linalg.norm(b_vec, axis=-1)
    angle_now = np.arccos(np.clip(np.sum(a_vec * b_vec, axis=-1) / np.maximum(a * b, 1e-12), -1.0, 1.0))
    # Law of cosines: the angle between base->root and base->goal at which |root - goal| = reach.
    cos_enough = (a**2 + b**2 - reach**2) / np.maximum(2.0 * a * b, 1e-12)
    angle_enough = np.arccos(np.clip(cos_enough, -1.0, 1.0))
    turn = np.clip(angle_now - angle_enough, 0.0, max_angle)
    return rotation_toward(a_vec, b_vec, weight=np.where(angle_now > 1e-12, turn / np.maximum(angle_now, 1e-12), 0.0))


def flexion(fraction: F64, upper: F64, lower: F64) -> F64:
    """Middle-joint flexion (radians, 0 = straight) of a limb at ``fraction`` of its length."""
    span = fraction * (upper + lower)
    return np.arccos(np.clip((span**2 - upper**2 - lower**2) / (2 * upper * lower), -1.0, 1.0))


def point_in_limb(upper: F64, lower: F64, fraction: F64, on_lower: NDArray[np.bool_], q: F64) -> F64:
    """A limb point's coordinates in the half-plane frame (n, 3), with the root at the origin.

    ``q`` (n, 3) is the point in its bone's frame (z along the bone from its proximal joint,
    x the limb normal); ``on_lower`` (n,) says which bone (upper: thigh, upper arm; lower:
    shank, forearm, and what hangs from it)."""
    span = np.clip(fraction * (upper + lower), np.abs(upper - lower) + 1e-9, upper + lower)
    y_e, z_e = two_sphere_middle(upper, lower, span)  # span >= 1e-9: no division clamped
    zeros = np.zeros_like(span)
    middle = np.stack([zeros, y_e, z_e], axis=-1)
    upper_dir = middle / upper[..., None]
    lower_dir = np.stack([zeros, -y_e, span - z_e], axis=-1) / lower[..., None]
    d = np.where(on_lower[..., None], lower_dir, upper_dir)
    origin = np.where(on_lower[..., None], middle, 0.0)
    # Bone frame: x = limb normal, z = d, y = z × x = (0, d_z, -d_y).
    y_axis = np.stack([zeros, d[..., 2], -d[..., 1]], axis=-1)
    point: F64 = origin + q[..., :1] * np.array([1.0, 0.0, 0.0]) + q[..., 1:2] * y_axis + q[..., 2:3] * d
    return point


def reach_point(root: F64, limb2world: F64, upper: F64, lower: F64, fraction: F64,
                on_lower: NDArray[np.bool_], q: F64, goal: F64,
                max_extension: float = 1.0) -> tuple[F64, F64, F64]:
    """Bring a point of a limb (its bone coordinates ``q``) onto ``goal`` (n, 3), analytically.

    The flexion is chosen so the point lies at the goal's distance from the root (the closest
    distance the limb allows when it cannot: the error is then the geometric minimum), the
    nearest such flexion to the current one; then the half-plane turns by the smallest rotation
    aiming the point at the goal. A point on the upper bone only turns the limb.
    Returns (limb2world (n, 3, 3), fraction (n,), the point's new position (n, 3)).
    """
    uu, ll = upper, lower
    phi_now = flexion(fraction, uu, ll)
    distance = np.linalg.norm(goal - root, axis=-1)
    wanted = (distance**2 - uu**2 - np.sum(q * q, axis=-1)) / (2.0 * uu)
    r = np.hypot(q[..., 1], q[..., 2])
    delta = np.arctan2(q[..., 1], q[..., 2])
    phi_lo = flexion(np.full_like(uu, max_extension), uu, ll)
    phi_hi = np.pi - 1e-3
    spread = np.arccos(np.clip(wanted / np.maximum(r, 1e-12), -1.0, 1.0))
    candidates = np.stack([delta + spread, delta - spread, delta, delta + np.pi,
                           phi_lo, np.full_like(uu, phi_hi), phi_now], axis=-1)
    # cos is 2π-periodic: wrap into (-π, π] (which holds the flexion range) before clipping.
    candidates = np.clip((candidates + np.pi) % (2 * np.pi) - np.pi, phi_lo[..., None], phi_hi)
    miss = np.abs(r[..., None] * np.cos(candidates - delta[..., None]) - wanted[..., None])
    best = np.argmin(miss + 1e-9 * np.abs(candidates - phi_now[..., None]), axis=-1)
    phi = np.take_along_axis(candidates, best[..., None], axis=-1)[..., 0]
    phi = np.where(on_lower, phi, phi_now)
    span = np.sqrt(np.maximum(uu**2 + ll**2 + 2 * uu * ll * np.cos(phi), 0.0))
    new_fraction = np.where(on_lower, span / (uu + ll), fraction)
    local = point_in_limb(uu, ll, new_fraction, on_lower, q)
    now = np.einsum("...ij,...j->...i", limb2world, local)
    frame = rotation_toward(now, goal - root) @ limb2world
    return frame, new_fraction, root + np.einsum("...ij,...j->...i", frame, local)


def turn_about_axis(root: F64, axis_through: F64, point: F64, goal: F64) -> F64:
    """The rotation (n, 3, 3) about the line root -> ``axis_through`` bringing ``point`` closest
    to ``goal`` (paper fig. 11 b: a lower-priority point moves on the circle that keeps the
    higher-priority one fixed). Where the point or goal lies on the axis: the identity."""
    k = normalize(axis_through - root)
    v, t = point - root, goal - root
    v = v - np.sum(v * k, axis=-1, keepdims=True) * k
    t = t - np.sum(t * k, axis=-1, keepdims=True) * k
    angle = np.arctan2(np.sum(k * np.cross(v, t), axis=-1), np.sum(v * t, axis=-1))
    ok = (np.linalg.norm(v, axis=-1) > 1e-9) & (np.linalg.norm(t, axis=-1) > 1e-9)
    return axis_angle(k, np.where(ok, angle, 0.0))


def middle_after_root_move(root: F64, end: F64, limb2world: F64, upper: F64, lower: F64,
                           move: F64) -> F64:
    """Where the middle joint (knee, elbow) of a limb goes when its root moves by ``move`` and
    :func:`reach_point` puts its end back on ``end``: the flexion for the new root-end span,
    and the half-plane turned by the smallest rotation of its ``z`` axis (root -> end) onto the
    new root-end direction. ``root``, ``end``, ``move`` (n, 3) m; ``limb2world`` (n, 3, 3)
    the half-plane frame now; ``upper``, ``lower`` (n,) m; the span must be within reach.
    Returns (n, 3)."""
    z_now, y_now = limb2world[..., :, 2], limb2world[..., :, 1]
    moved = root + move
    to_end = end - moved
    span = np.linalg.norm(to_end, axis=-1)
    z_new = to_end / span[..., None]
    y_middle, z_middle = two_sphere_middle(upper, lower, span)
    # The smallest rotation taking z_now onto z_new (Rodrigues' formula with sin and cos
    # given by the cross and dot products), applied to the half-plane's y axis.
    axis = np.cross(z_now, z_new)
    cos = np.sum(z_now * z_new, axis=-1)
    y_new = (y_now * cos[..., None] + np.cross(axis, y_now)
             + axis * (np.sum(axis * y_now, axis=-1) / (1.0 + cos))[..., None])
    middle: F64 = moved + y_new * y_middle[..., None] + z_new * z_middle[..., None]
    return middle
