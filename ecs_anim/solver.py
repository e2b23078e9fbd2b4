"""Constraint-solver steps on limbs of variable length (paper §9, fig. 11), as pure batched kernels.

A limb (arm or leg) is its root joint, its half-plane frame (``z`` root -> end, ``y`` towards the
middle joint) and its length fraction. The steps here return a new frame and fraction; the
solver shell (the constraint issue's ConstraintSolve) owns priorities, iterations and blending.

* :func:`reach` — the high-priority step: put the limb's end on a target analytically; out of
  reach, stretch the limb straight towards it (the error is then the geometric minimum).
* :func:`swivel` — a lower-priority step: turn the limb about its root -> end axis (so the end,
  and any higher-priority constraint on it, stays exactly where it is) to bring the middle joint
  as close as possible to a target: the best point on the circle of solutions (fig. 11 b).

Shapes: ``(n, 3)`` points, ``(n, 3, 3)`` frames (axes as columns), ``(n,)`` lengths in metres.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .rotations import normalize, rotation_between

F64 = NDArray[np.float64]


def reach(root: F64, limb2world: F64, upper: F64, lower: F64, target: F64,
          max_extension: float = 1.0) -> tuple[F64, F64, F64]:
    """Aim a limb's end at ``target`` (paper §9: analytic computation for limbs).

    The half-plane turns by the smallest rotation taking its ``z`` onto root -> target, so the
    middle joint keeps its side. Returns (new limb2world (n, 3, 3), new fraction (n,), end
    position (n, 3)); the fraction is clamped to what the bones can span
    (``|upper - lower|`` to ``max_extension × (upper + lower)``).
    """
    to_target = target - root
    distance = np.linalg.norm(to_target, axis=-1)
    total = upper + lower
    reachable = np.clip(distance, np.abs(upper - lower), max_extension * total)
    turn = rotation_between(limb2world[..., :, 2], to_target)
    frame = turn @ limb2world
    end = root + frame[..., :, 2] * reachable[..., None]
    return frame, reachable / total, end


def middle_joint(root: F64, limb2world: F64, upper: F64, lower: F64, fraction: F64) -> F64:
    """The middle joint (elbow, knee) of a limb: two-sphere intersection in its half-plane."""
    span = np.clip(fraction * (upper + lower), np.abs(upper - lower), upper + lower)
    safe = np.maximum(span, 1e-12)
    z = (upper**2 - lower**2 + span**2) / (2.0 * safe)
    y = np.sqrt(np.maximum(upper**2 - z**2, 0.0))
    return root + limb2world[..., :, 1] * y[..., None] + limb2world[..., :, 2] * z[..., None]


def swivel(root: F64, limb2world: F64, middle_target: F64, weight: F64 | None = None) -> F64:
    """Turn the half-plane about its own ``z`` (root -> end) towards ``middle_target``.

    The middle joint then lies on the side of the axis closest to the target; the end joint does
    not move. ``weight`` (n,) in [0, 1] turns only that part of the way (activation ramps).
    Where the target lies on the axis, the frame is unchanged. Returns limb2world (n, 3, 3).
    """
    axis = limb2world[..., :, 2]
    offset = middle_target - root
    perpendicular = offset - np.sum(offset * axis, axis=-1, keepdims=True) * axis
    has_side = np.linalg.norm(perpendicular, axis=-1) > 1e-12
    y_now, x_now = limb2world[..., :, 1], limb2world[..., :, 0]
    # Angle about z from the current y towards the wanted side.
    angle = np.arctan2(np.sum(perpendicular * -x_now, axis=-1), np.sum(perpendicular * y_now, axis=-1))
    angle = np.where(has_side, angle, 0.0)
    if weight is not None:
        angle = angle * np.clip(weight, 0.0, 1.0)
    c, s = np.cos(angle)[..., None], np.sin(angle)[..., None]
    # Rotating about z by angle: y -> c y - s x ... expressed with the frame's own axes.
    new_y = c * y_now - s * x_now
    new_x = c * x_now + s * y_now
    out = limb2world.copy()
    out[..., :, 0] = normalize(new_x)
    out[..., :, 1] = normalize(new_y)
    return out
