"""Batched rotation helpers.

Conventions (pinned by ``tests/core/test_rotations.py``): rotation matrices act on column vectors
(``v_in_world = pelvis2world @ v_in_pelvis``); a frame's matrix holds its axes as columns;
quaternions are unit, scalar-last ``(x, y, z, w)``; angles are radians unless a name says
``_deg``. Every function takes any number of leading batch axes.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]
TINY = 1e-12


def normalize(v: F64) -> F64:
    """Unit vectors (or quaternions) along the last axis; zero ones stay zero.
    Shape (..., k) -> (..., k)."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    unit: F64 = v / np.maximum(n, TINY)
    return unit


def rot_axis(axis: int, angle: F64 | float) -> F64:
    """Rotations by ``angle`` (radians, shape (...)) about a coordinate axis (0=x, 1=y, 2=z).

    Returns shape (..., 3, 3).
    """
    angle = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(angle), np.sin(angle)
    out = np.zeros(angle.shape + (3, 3))
    i, j = (axis + 1) % 3, (axis + 2) % 3
    out[..., axis, axis] = 1.0
    out[..., i, i] = c
    out[..., j, j] = c
    out[..., i, j] = -s
    out[..., j, i] = s
    return out


def cross_matrix(k: F64) -> F64:
    """The matrices ``[k]x`` with ``[k]x @ v == cross(k, v)``. Shape (..., 3) -> (..., 3, 3)."""
    kx = np.zeros(k.shape[:-1] + (3, 3))
    kx[..., 0, 1], kx[..., 0, 2] = -k[..., 2], k[..., 1]
    kx[..., 1, 0], kx[..., 1, 2] = k[..., 2], -k[..., 0]
    kx[..., 2, 0], kx[..., 2, 1] = -k[..., 1], k[..., 0]
    return kx


def axis_angle(axis: F64, angle: F64) -> F64:
    """Rotations by ``angle`` (...) radians about unit ``axis`` (..., 3) (Rodrigues: R = I +
    sin(angle) [k]x + (1 - cos(angle)) [k]x^2). Returns (..., 3, 3)."""
    kx = cross_matrix(axis)
    s, c = np.sin(angle)[..., None, None], np.cos(angle)[..., None, None]
    rotation: F64 = np.eye(3) + s * kx + (1.0 - c) * (kx @ kx)
    return rotation


def euler_to_matrix(angles_deg: F64, order: str) -> F64:
    """Matrices from intrinsic Euler angles in BVH channel order.

    ``order`` is e.g. ``"ZXY"``: the joint's rotation is ``Rz @ Rx @ Ry`` with the angles taken
    from the last axis of ``angles_deg`` in that same order. Shape (..., 3) -> (..., 3, 3).
    """
    rad = np.deg2rad(angles_deg)
    out = rot_axis("XYZ".index(order[0]), rad[..., 0])
    for k in (1, 2):
        out = out @ rot_axis("XYZ".index(order[k]), rad[..., k])
    return out


def matrix_to_euler(matrix: F64, order: str) -> F64:
    """Intrinsic Euler angles (degrees, in ``order``) of rotation matrices; inverse of
    :func:`euler_to_matrix` (at gimbal lock the last angle is set to 0).

    Shape (..., 3, 3) -> (..., 3).
    """
    a, b, c = ("XYZ".index(ch) for ch in order)
    if len({a, b, c}) != 3:
        raise ValueError(f"Euler order {order!r} must name three different axes")
    # Sign of the permutation (a, b, c): +1 for cyclic orders like XYZ, YZX, ZXY.
    sign = 1.0 if (b - a) % 3 == 1 else -1.0
    m = matrix
    # For R = R_a(t1) R_b(t2) R_c(t3): m[a, c] = sign * sin(t2).
    sin_t2 = np.clip(sign * m[..., a, c], -1.0, 1.0)
    t2 = np.arcsin(sin_t2)
    cos_t2 = np.sqrt(np.maximum(1.0 - sin_t2 * sin_t2, 0.0))
    regular = cos_t2 > 1e-9
    t1 = np.arctan2(-sign * m[..., b, c], m[..., c, c])
    t3 = np.arctan2(-sign * m[..., a, b], m[..., a, a])
    # Gimbal lock: only t1 + sign*t3 is defined; put it all on t1.
    t1_locked = np.arctan2(sign * m[..., c, b], m[..., b, b])
    t1 = np.where(regular, t1, t1_locked)
    t3 = np.where(regular, t3, 0.0)
    degrees: F64 = np.rad2deg(np.stack([t1, t2, t3], axis=-1))
    return degrees


def quat_from_matrix(matrix: F64) -> F64:
    """Unit quaternions (x, y, z, w), w >= 0, from rotation matrices. (..., 3, 3) -> (..., 4)."""
    m = matrix
    trace = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    # Four candidate formulas; pick per element the numerically best (largest denominator).
    cands = np.stack(
        [
            np.stack([m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0],
                      m[..., 1, 0] - m[..., 0, 1], 1.0 + trace], axis=-1),
            np.stack([1.0 + m[..., 0, 0] - m[..., 1, 1] - m[..., 2, 2],
                      m[..., 0, 1] + m[..., 1, 0], m[..., 0, 2] + m[..., 2, 0],
                      m[..., 2, 1] - m[..., 1, 2]], axis=-1),
            np.stack([m[..., 0, 1] + m[..., 1, 0],
                      1.0 - m[..., 0, 0] + m[..., 1, 1] - m[..., 2, 2],
                      m[..., 1, 2] + m[..., 2, 1], m[..., 0, 2] - m[..., 2, 0]], axis=-1),
            np.stack([m[..., 0, 2] + m[..., 2, 0], m[..., 1, 2] + m[..., 2, 1],
                      1.0 - m[..., 0, 0] - m[..., 1, 1] + m[..., 2, 2],
                      m[..., 1, 0] - m[..., 0, 1]], axis=-1),
        ],
        axis=-2,
    )
    diag = np.stack([trace, m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]], axis=-1)
    best = np.argmax(diag, axis=-1)
    q = np.take_along_axis(cands, best[..., None, None], axis=-2)[..., 0, :]
    q = q / np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), TINY)
    positive_w: F64 = np.where(q[..., 3:4] < 0.0, -q, q)
    return positive_w


def quat_mul(a: F64, b: F64) -> F64:
    """Hamilton products ``a b`` of quaternions (..., 4), (x, y, z, w)."""
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz], axis=-1)


def quat_conj(q: F64) -> F64:
    """Conjugates (..., 4) of quaternions (x, y, z, w): the inverse turns of unit ones."""
    conjugate: F64 = q * np.array([-1.0, -1.0, -1.0, 1.0])
    return conjugate


def quat_between(a: F64, b: F64) -> F64:
    """Quaternions (..., 4), (x, y, z, w), of the smallest turns taking unit directions ``a``
    onto ``b`` (..., 3) (a half turn about an axis perpendicular to ``a`` for opposite ones)."""
    c = np.sum(a * b, axis=-1)
    q = np.concatenate([np.cross(a, b), (1.0 + c)[..., None]], axis=-1)
    opposite = c < -1.0 + 1e-9
    if np.any(opposite):
        helper = np.where(np.abs(a[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        half = np.concatenate([np.cross(a, helper), np.zeros_like(c)[..., None]], axis=-1)
        q = np.where(opposite[..., None], half, q)
    out: F64 = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return out


def quat_rotate(q: F64, v: F64) -> F64:
    """``v`` (..., 3) turned by the unit quaternions ``q`` (..., 4)."""
    u, w = q[..., :3], q[..., 3:]
    t = 2.0 * np.cross(u, v)
    out: F64 = v + w * t + np.cross(u, t)
    return out


def matrix_from_quat(quat: F64) -> F64:
    """Rotation matrices from quaternions (x, y, z, w); normalizes first. (..., 4) -> (..., 3, 3)."""
    q = quat / np.maximum(np.linalg.norm(quat, axis=-1, keepdims=True), TINY)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    out = np.empty(q.shape[:-1] + (3, 3))
    out[..., 0, 0] = 1 - 2 * (y * y + z * z)
    out[..., 0, 1] = 2 * (x * y - z * w)
    out[..., 0, 2] = 2 * (x * z + y * w)
    out[..., 1, 0] = 2 * (x * y + z * w)
    out[..., 1, 1] = 1 - 2 * (x * x + z * z)
    out[..., 1, 2] = 2 * (y * z - x * w)
    out[..., 2, 0] = 2 * (x * z - y * w)
    out[..., 2, 1] = 2 * (y * z + x * w)
    out[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return out


def frame_from_axes(primary: F64, secondary: F64, primary_axis: int, secondary_axis: int,
                    fallback_secondary: F64 | None = None) -> F64:
    """Right-handed frames with ``primary`` as axis ``primary_axis`` and ``secondary``
    (made orthogonal to it) as axis ``secondary_axis``.

    Where ``secondary`` is (nearly) parallel to ``primary``, ``fallback_secondary`` is used
    instead (if given). Shapes (..., 3) -> (..., 3, 3), axes as columns.
    """
    p = normalize(primary)
    s = secondary - np.sum(secondary * p, axis=-1, keepdims=True) * p
    if fallback_secondary is not None:
        fb = fallback_secondary - np.sum(fallback_secondary * p, axis=-1, keepdims=True) * p
        weak = np.linalg.norm(s, axis=-1, keepdims=True) < 1e-9
        s = np.where(weak, fb, s)
    s = normalize(s)
    third_axis = 3 - primary_axis - secondary_axis
    # cross(e_i, e_j) = +e_k for cyclic (i, j, k).
    cyclic = (secondary_axis - primary_axis) % 3 == 1
    t = np.cross(p, s) if cyclic else np.cross(s, p)
    out = np.empty(p.shape[:-1] + (3, 3))
    out[..., :, primary_axis] = p
    out[..., :, secondary_axis] = s
    out[..., :, third_axis] = t
    return out


def rotation_between(a: F64, b: F64) -> F64:
    """Smallest rotations taking directions ``a`` onto ``b`` (the 'swing').

    For opposite directions, a half turn about an axis perpendicular to ``a``.
    Shapes (..., 3) -> (..., 3, 3).
    """
    a = normalize(a)
    b = normalize(b)
    axis = np.cross(a, b)
    s = np.linalg.norm(axis, axis=-1)
    c = np.sum(a * b, axis=-1)
    # Rodrigues with k = axis (unnormalized, |k| = sin): R = I + [k]x + [k]x^2 / (1 + c).
    kx = cross_matrix(axis)
    eye = np.broadcast_to(np.eye(3), kx.shape)
    denom = np.maximum(1.0 + c, 1e-12)[..., None, None]
    out: F64 = eye + kx + kx @ kx / denom
    # Opposite directions: rotate by pi about any axis perpendicular to a.
    opposite = (c < -1.0 + 1e-9) & (s < 1e-6)
    if np.any(opposite):
        helper = np.where(np.abs(a[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        perp = normalize(np.cross(a, helper))
        half_turn = 2.0 * perp[..., :, None] * perp[..., None, :] - eye
        out = np.where(opposite[..., None, None], half_turn, out)
    return out


def yaw_of(frame: F64) -> F64:
    """Heading (radians about world Z) of a frame's x axis. (..., 3, 3) -> (...)."""
    return np.arctan2(frame[..., 1, 0], frame[..., 0, 0])


def slerp(q0: F64, q1: F64, t: F64 | float) -> F64:
    """Spherical interpolation of quaternions (x, y, z, w) along the shorter arc.

    ``q0``, ``q1`` shape (..., 4); ``t`` shape (...) in [0, 1]. Returns (..., 4).
    """
    t = np.asarray(t, dtype=np.float64)[..., None]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0.0, -q1, q1)
    dot = np.clip(np.abs(dot), 0.0, 1.0)
    theta = np.arccos(dot)
    # The sum is normalized: the weights need not be divided by sin(theta), which is only
    # compared (squared, as 1 - cos^2: no sine) with 1e-6, where the arc is too short to tell.
    near = (1.0 - dot) * (1.0 + dot) < 1e-12
    w0 = np.where(near, 1.0 - t, np.sin((1.0 - t) * theta))
    w1 = np.where(near, t, np.sin(t * theta))
    return normalize(w0 * q0 + w1 * q1)
