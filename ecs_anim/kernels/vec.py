"""Scalar helpers the compiled kernels share (numba ``njit``, no fastmath).

A 3-vector is a tuple ``(x, y, z)``; a quaternion a tuple ``(x, y, z, w)`` (scalar last); a
frame (rotation matrix) is the tuple of its three axes, its columns: ``(x_axis, y_axis, z_axis)``,
so ``to_world(pelvis2world, v_in_pelvis)`` is ``pelvis2world @ v``. Each helper names the numpy
function of :mod:`ecs_anim.rotations` or :mod:`ecs_anim.normalized` it mirrors.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

F64 = NDArray[np.float64]
Vec3 = tuple[float, float, float]
#: Scalar last: (x, y, z, w).
Quat = tuple[float, float, float, float]
#: A rotation matrix as its three axes (columns): (x_axis, y_axis, z_axis).
Frame = tuple[Vec3, Vec3, Vec3]

#: As :data:`ecs_anim.rotations.TINY`: the smallest norm divided by.
TINY = 1e-12


@njit(cache=True)
def add(a: Vec3, b: Vec3) -> Vec3:
    """``a + b``."""
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@njit(cache=True)
def sub(a: Vec3, b: Vec3) -> Vec3:
    """``a - b``."""
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@njit(cache=True)
def scale(a: Vec3, s: float) -> Vec3:
    """``a * s`` for a scalar ``s``."""
    return (a[0] * s, a[1] * s, a[2] * s)


@njit(cache=True)
def add_scaled(a: Vec3, b: Vec3, s: float) -> Vec3:
    """``a + b * s``."""
    return (a[0] + b[0] * s, a[1] + b[1] * s, a[2] + b[2] * s)


@njit(cache=True)
def dot(a: Vec3, b: Vec3) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True)
def cross(a: Vec3, b: Vec3) -> Vec3:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True)
def norm(a: Vec3) -> float:
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


@njit(cache=True)
def normalize(a: Vec3) -> Vec3:
    """Mirrors :func:`ecs_anim.rotations.normalize` for one 3-vector (zero stays zero)."""
    n = max(norm(a), TINY)
    return (a[0] / n, a[1] / n, a[2] / n)


@njit(cache=True)
def to_world(m: Frame, v: Vec3) -> Vec3:
    """``m @ v`` (mirrors ``normalized._to_world``): ``v`` given in the frame ``m``, in its parent."""
    x, y, z = m
    return (x[0] * v[0] + y[0] * v[1] + z[0] * v[2],
            x[1] * v[0] + y[1] * v[1] + z[1] * v[2],
            x[2] * v[0] + y[2] * v[1] + z[2] * v[2])


@njit(cache=True)
def in_frame(m: Frame, v: Vec3) -> Vec3:
    """``m.T @ v`` (mirrors ``normalized._in_frame``): a parent-frame vector in the frame ``m``."""
    return (dot(m[0], v), dot(m[1], v), dot(m[2], v))


@njit(cache=True)
def matmul(a: Frame, b: Frame) -> Frame:
    """``a @ b``: the frame ``b`` (given in ``a``) in ``a``'s parent."""
    return (to_world(a, b[0]), to_world(a, b[1]), to_world(a, b[2]))


@njit(cache=True)
def transpose(m: Frame) -> Frame:
    x, y, z = m
    return ((x[0], y[0], z[0]), (x[1], y[1], z[1]), (x[2], y[2], z[2]))


@njit(cache=True)
def rot_z(angle: float) -> Frame:
    """Mirrors ``rotations.rot_axis(2, angle)``."""
    c, s = math.cos(angle), math.sin(angle)
    return ((c, s, 0.0), (-s, c, 0.0), (0.0, 0.0, 1.0))


@njit(cache=True)
def matrix_from_quat(q: Quat) -> Frame:
    """Mirrors :func:`ecs_anim.rotations.matrix_from_quat` (normalizes first)."""
    n = max(math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]), TINY)
    x, y, z, w = q[0] / n, q[1] / n, q[2] / n, q[3] / n
    return ((1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w)),
            (2 * (x * y - z * w), 1 - 2 * (x * x + z * z), 2 * (y * z + x * w)),
            (2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y)))


@njit(cache=True)
def quat_from_matrix(m: Frame) -> Quat:
    """Mirrors :func:`ecs_anim.rotations.quat_from_matrix` (w >= 0)."""
    # m[col][row]: element (row i, column j) is m[j][i].
    m00, m11, m22 = m[0][0], m[1][1], m[2][2]
    m01, m02, m10, m12, m20, m21 = m[1][0], m[2][0], m[0][1], m[2][1], m[0][2], m[1][2]
    trace = m00 + m11 + m22
    best, largest = 0, trace
    if m00 > largest:
        best, largest = 1, m00
    if m11 > largest:
        best, largest = 2, m11
    if m22 > largest:
        best = 3
    if best == 0:
        q = (m21 - m12, m02 - m20, m10 - m01, 1.0 + trace)
    elif best == 1:
        q = (1.0 + m00 - m11 - m22, m01 + m10, m02 + m20, m21 - m12)
    elif best == 2:
        q = (m01 + m10, 1.0 - m00 + m11 - m22, m12 + m21, m02 - m20)
    else:
        q = (m02 + m20, m12 + m21, 1.0 - m00 - m11 + m22, m10 - m01)
    n = max(math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]), TINY)
    sign = -1.0 if q[3] / n < 0.0 else 1.0
    return (sign * q[0] / n, sign * q[1] / n, sign * q[2] / n, sign * q[3] / n)


@njit(cache=True)
def frame_from_axes(primary: Vec3, secondary: Vec3, primary_axis: int, secondary_axis: int,
                    fallback_secondary: Vec3) -> Frame:
    """Mirrors :func:`ecs_anim.rotations.frame_from_axes` with a fallback always given (pass
    ``secondary`` again for none: it is only used where ``secondary`` is parallel to ``primary``)."""
    p = normalize(primary)
    s = add_scaled(secondary, p, -dot(secondary, p))
    if norm(s) < 1e-9:
        s = add_scaled(fallback_secondary, p, -dot(fallback_secondary, p))
    s = normalize(s)
    cyclic = (secondary_axis - primary_axis) % 3 == 1
    t = cross(p, s) if cyclic else cross(s, p)
    third_axis = 3 - primary_axis - secondary_axis
    axes = [p, p, p]
    axes[primary_axis] = p
    axes[secondary_axis] = s
    axes[third_axis] = t
    return (axes[0], axes[1], axes[2])


@njit(cache=True)
def rotation_between(a: Vec3, b: Vec3) -> Frame:
    """Mirrors :func:`ecs_anim.rotations.rotation_between`: the smallest rotation taking the
    direction ``a`` onto ``b`` (a half turn for opposite directions)."""
    a = normalize(a)
    b = normalize(b)
    k = cross(a, b)
    s = norm(k)
    c = dot(a, b)
    if c < -1.0 + 1e-9 and s < 1e-6:
        helper = (1.0, 0.0, 0.0) if abs(a[0]) < 0.9 else (0.0, 1.0, 0.0)
        p = normalize(cross(a, helper))
        return ((2.0 * p[0] * p[0] - 1.0, 2.0 * p[1] * p[0], 2.0 * p[2] * p[0]),
                (2.0 * p[0] * p[1], 2.0 * p[1] * p[1] - 1.0, 2.0 * p[2] * p[1]),
                (2.0 * p[0] * p[2], 2.0 * p[1] * p[2], 2.0 * p[2] * p[2] - 1.0))
    d = 1.0 / max(1.0 + c, 1e-12)
    # Rodrigues with the unnormalized axis k: R = I + [k]x + [k]x^2 / (1 + c), column by column;
    # column j of [k]x is k x e_j, of [k]x^2 is k x (k x e_j) = k k_j - e_j |k|^2.
    kk = dot(k, k)
    cols = []
    for j in range(3):
        e = (1.0 if j == 0 else 0.0, 1.0 if j == 1 else 0.0, 1.0 if j == 2 else 0.0)
        kxe = cross(k, e)
        kkxe = sub(scale(k, k[j]), scale(e, kk))
        cols.append(add(add(e, kxe), scale(kkxe, d)))
    return (cols[0], cols[1], cols[2])


@njit(cache=True)
def load3(a: F64) -> Vec3:
    """A 3-vector from a 1-D array view of length 3."""
    return (a[0], a[1], a[2])


@njit(cache=True)
def store3(out: F64, v: Vec3) -> None:
    out[0], out[1], out[2] = v[0], v[1], v[2]


@njit(cache=True)
def load4(a: F64) -> Quat:
    return (a[0], a[1], a[2], a[3])


@njit(cache=True)
def store4(out: F64, q: Quat) -> None:
    out[0], out[1], out[2], out[3] = q[0], q[1], q[2], q[3]


@njit(cache=True)
def load_frame(a: F64) -> Frame:
    """A frame from a (3, 3) array view holding its axes as columns (``a[row, column]``)."""
    return ((a[0, 0], a[1, 0], a[2, 0]), (a[0, 1], a[1, 1], a[2, 1]), (a[0, 2], a[1, 2], a[2, 2]))


@njit(cache=True)
def store_frame(out: F64, m: Frame) -> None:
    """Write a frame into a (3, 3) array view, axes as columns."""
    for j in range(3):
        for i in range(3):
            out[i, j] = m[j][i]
