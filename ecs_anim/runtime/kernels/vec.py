"""Scalar helpers the compiled kernels share, and :func:`jit`, the decorator of every kernel.

A 3-vector is a tuple ``(x, y, z)``; a quaternion a tuple ``(x, y, z, w)`` (scalar last); a
frame (rotation matrix) is the tuple of its three axes, its columns: ``(x_axis, y_axis, z_axis)``,
so ``to_world(pelvis2world, v_in_pelvis)`` is ``pelvis2world @ v``. Each helper names the numpy
function of :mod:`ecs_anim.core.rotations` or :mod:`ecs_anim.core.normalized` it mirrors.
"""

from __future__ import annotations

import math
import sys
import threading
from collections.abc import Callable
from typing import Any, TypeVar, cast

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]
Vec3 = tuple[float, float, float]
#: Scalar last: (x, y, z, w).
Quat = tuple[float, float, float, float]
#: A rotation matrix as its three axes (columns): (x_axis, y_axis, z_axis).
Frame = tuple[Vec3, Vec3, Vec3]

#: As :data:`ecs_anim.core.rotations.TINY`: the smallest norm divided by.
TINY = 1e-12


#: numba's ``njit`` options of every kernel of this package: cached on disk; numpy's error model
#: (a division by zero gives inf or nan, as in the numpy reference, instead of a test and a
#: raise at every division); never fastmath (it broke the 1e-9 m agreement with numpy); and
#: without numba's runtime (``_nrt``). The kernels allocate nothing (their callers pass every
#: array, scratch included) and the callers hold the arrays while they run, so the runtime's
#: reference counts bought nothing and cost an atomic operation at every array a step was
#: handed or a view taken: a third of playback's time and about 40 % of the solver's (perf
#: samples, 2026-12-02).
NJIT_OPTIONS: dict[str, Any] = {"cache": True, "error_model": "numpy", "_nrt": False}

KernelFunction = TypeVar("KernelFunction", bound=Callable[..., Any])
_waiting: list[PendingKernel] = []  # made before numba was imported, in the order made
_numba_lock = threading.RLock()
_njit: list[Callable[..., Any]] = []  # numba's njit once imported (:func:`with_numba`)
#: Called as numba is imported, before any kernel is compiled (:func:`on_numba_import`).
_on_numba_import: list[Callable[[], None]] = []


def on_numba_import(hook: Callable[[], None]) -> None:
    """Have :func:`with_numba` call ``hook`` as it imports numba, before any kernel compiles
    (at once where numba is imported already: a kernel module imported after a tick ran): the
    package registers where numba caches its kernels
    (:func:`ecs_anim.runtime.kernels.cache_kernels_in_cache_dir`), so this module, which every
    kernel imports, imports nothing of the package; the solver puts its compiled
    ``prefetch`` in place (:mod:`ecs_anim.runtime.kernels.solve`)."""
    with _numba_lock:
        if _njit:
            hook()
        else:
            _on_numba_import.append(hook)


class PendingKernel:
    """A kernel decorated before numba was imported: ``import ecs_anim`` costs no numba (0.6-0.8 s
    of CPU). The first call, attribute read or :func:`with_numba` imports numba, makes every
    pending kernel's dispatcher and puts them in place of their placeholders in the kernel
    modules (numba resolves a kernel's callees from its module's globals when it compiles);
    a placeholder kept elsewhere (``from ... import kernel`` in a system) forwards to it."""

    def __init__(self, py_func: Callable[..., Any], options: dict[str, Any]) -> None:
        self.py_func = py_func
        self.options = options
        self.dispatcher: Any = None
        self.__doc__ = py_func.__doc__
        self.__name__ = py_func.__name__
        self.__module__ = py_func.__module__
        self.__wrapped__ = py_func

    def __call__(self, *args: Any) -> Any:
        if self.dispatcher is None:
            with_numba()
        return self.dispatcher(*args)

    def __getattr__(self, name: str) -> Any:  # numba's Dispatcher's attributes (signatures, ...)
        if name == "dispatcher":
            raise AttributeError(name)
        with_numba()
        return getattr(self.dispatcher, name)


def with_numba() -> None:
    """Import numba (once), call the hooks of :func:`on_numba_import` (the package's: numba then
    caches its kernels in :func:`ecs_anim.runtime.kernels.cache_dir`, the solver's ``prefetch``
    compiled) and make the dispatchers
    of the kernels decorated before (:class:`PendingKernel`)."""
    if _njit and not _waiting:
        return
    with _numba_lock:
        if not _njit:
            from numba import njit

            for hook in _on_numba_import:
                hook()
            _njit.append(njit)
        pending = {id(p): p for p in _waiting}
        for kernel in _waiting:
            kernel.dispatcher = _njit[0](**NJIT_OPTIONS, **kernel.options)(kernel.py_func)
        _waiting.clear()
        for name, module in list(sys.modules.items()):
            if name.startswith("ecs_anim.runtime.kernels.") and module is not None:
                names = vars(module)
                for key, value in list(names.items()):
                    if id(value) in pending:
                        names[key] = value.dispatcher


def jit(**options: Any) -> Callable[[KernelFunction], KernelFunction]:
    """The decorator of every kernel: numba's ``njit`` with :data:`NJIT_OPTIONS` and ``options``
    (``jit()``, ``jit(nogil=True)``, ``jit(inline="always")``); a :class:`PendingKernel` until
    numba is imported."""

    def decorate(py_func: KernelFunction) -> KernelFunction:
        with _numba_lock:
            if _njit:
                return cast("KernelFunction", _njit[0](**NJIT_OPTIONS, **options)(py_func))
            kernel = PendingKernel(py_func, options)
            _waiting.append(kernel)
            return cast("KernelFunction", kernel)

    return decorate


@jit()
def add(a: Vec3, b: Vec3) -> Vec3:
    """``a + b``."""
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@jit()
def sub(a: Vec3, b: Vec3) -> Vec3:
    """``a - b``."""
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@jit()
def scale(a: Vec3, s: float) -> Vec3:
    """``a * s`` for a scalar ``s``."""
    return (a[0] * s, a[1] * s, a[2] * s)


@jit()
def add_scaled(a: Vec3, b: Vec3, s: float) -> Vec3:
    """``a + b * s``."""
    return (a[0] + b[0] * s, a[1] + b[1] * s, a[2] + b[2] * s)


@jit()
def dot(a: Vec3, b: Vec3) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@jit()
def cross(a: Vec3, b: Vec3) -> Vec3:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@jit()
def norm(a: Vec3) -> float:
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


@jit()
def normalize(a: Vec3) -> Vec3:
    """Mirrors :func:`ecs_anim.core.rotations.normalize` for one 3-vector (zero stays zero)."""
    n = max(norm(a), TINY)
    return (a[0] / n, a[1] / n, a[2] / n)


@jit()
def to_world(m: Frame, v: Vec3) -> Vec3:
    """``m @ v`` (mirrors ``normalized._to_world``): ``v`` given in the frame ``m``, in its parent."""
    x, y, z = m
    return (x[0] * v[0] + y[0] * v[1] + z[0] * v[2],
            x[1] * v[0] + y[1] * v[1] + z[1] * v[2],
            x[2] * v[0] + y[2] * v[1] + z[2] * v[2])


@jit()
def in_frame(m: Frame, v: Vec3) -> Vec3:
    """``m.T @ v`` (mirrors ``normalized._in_frame``): a parent-frame vector in the frame ``m``."""
    return (dot(m[0], v), dot(m[1], v), dot(m[2], v))


@jit()
def matmul(a: Frame, b: Frame) -> Frame:
    """``a @ b``: the frame ``b`` (given in ``a``) in ``a``'s parent."""
    return (to_world(a, b[0]), to_world(a, b[1]), to_world(a, b[2]))


@jit()
def transpose(m: Frame) -> Frame:
    x, y, z = m
    return ((x[0], y[0], z[0]), (x[1], y[1], z[1]), (x[2], y[2], z[2]))


@jit()
def rot_z(angle: float) -> Frame:
    """Mirrors ``rotations.rot_axis(2, angle)``."""
    c, s = math.cos(angle), math.sin(angle)
    return ((c, s, 0.0), (-s, c, 0.0), (0.0, 0.0, 1.0))


@jit()
def matrix_from_quat(q: Quat) -> Frame:
    """Mirrors :func:`ecs_anim.core.rotations.matrix_from_quat` (normalizes first)."""
    n = max(math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]), TINY)
    x, y, z, w = q[0] / n, q[1] / n, q[2] / n, q[3] / n
    return ((1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w)),
            (2 * (x * y - z * w), 1 - 2 * (x * x + z * z), 2 * (y * z + x * w)),
            (2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y)))


@jit()
def rotation_from_quat(q: Quat) -> Frame:
    """:func:`matrix_from_quat` to rounding, for the decode: the norm folded into one factor
    ``2 / |q|^2`` (one division and no square root where the normalization takes four and
    one). Not the same bits: the ground adaptation's legs keep ``matrix_from_quat`` (its
    footprints steer crowds, where a last bit changed moves a walker's path)."""
    x, y, z, w = q
    s = 2.0 / max(x * x + y * y + z * z + w * w, TINY * TINY)
    xs, ys, zs = x * s, y * s, z * s
    xx, xy, xz = x * xs, x * ys, x * zs
    yy, yz, zz = y * ys, y * zs, z * zs
    wx, wy, wz = w * xs, w * ys, w * zs
    return ((1.0 - (yy + zz), xy + wz, xz - wy),
            (xy - wz, 1.0 - (xx + zz), yz + wx),
            (xz + wy, yz - wx, 1.0 - (xx + yy)))


@jit()
def quat_mul(a: Quat, b: Quat) -> Quat:
    """Mirrors :func:`ecs_anim.core.rotations.quat_mul`: the Hamilton product ``a b``."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


@jit()
def quat_from_matrix(m: Frame) -> Quat:
    """Mirrors :func:`ecs_anim.core.rotations.quat_from_matrix` (w >= 0)."""
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


@jit()
def frame_from_axes(primary: Vec3, secondary: Vec3, primary_axis: int, secondary_axis: int,
                    fallback_secondary: Vec3) -> Frame:
    """Mirrors :func:`ecs_anim.core.rotations.frame_from_axes` with a fallback always given (pass
    ``secondary`` again for none: it is only used where ``secondary`` is parallel to ``primary``).
    No list (numba allocates lists on the heap: about 0.2 us a call)."""
    p = normalize(primary)
    s = add_scaled(secondary, p, -dot(secondary, p))
    if norm(s) < 1e-9:
        s = add_scaled(fallback_secondary, p, -dot(fallback_secondary, p))
    s = normalize(s)
    cyclic = (secondary_axis - primary_axis) % 3 == 1
    t = cross(p, s) if cyclic else cross(s, p)
    x = p if primary_axis == 0 else (s if secondary_axis == 0 else t)
    y = p if primary_axis == 1 else (s if secondary_axis == 1 else t)
    z = p if primary_axis == 2 else (s if secondary_axis == 2 else t)
    return (x, y, z)


@jit()
def rotation_between(a: Vec3, b: Vec3) -> Frame:
    """Mirrors :func:`ecs_anim.core.rotations.rotation_between`: the smallest rotation taking the
    direction ``a`` onto ``b`` (a half turn for opposite directions). No list (numba allocates
    lists on the heap)."""
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
    # Rodrigues with the unnormalized axis k: R = I + [k]x + [k]x^2 / (1 + c), column by column.
    kk = dot(k, k)
    return (_rodrigues_column(k, kk, d, (1.0, 0.0, 0.0), k[0]),
            _rodrigues_column(k, kk, d, (0.0, 1.0, 0.0), k[1]),
            _rodrigues_column(k, kk, d, (0.0, 0.0, 1.0), k[2]))


@jit()
def _rodrigues_column(k: Vec3, kk: float, d: float, e: Vec3, k_j: float) -> Vec3:
    """Column ``j`` of ``I + [k]x + [k]x^2 d`` (``e`` = e_j, ``k_j`` = k[j], ``kk`` = |k|^2):
    ``e + k x e + (k k_j - e |k|^2) d`` (column j of ``[k]x`` is ``k x e_j``, of ``[k]x^2``
    ``k k_j - e_j |k|^2``), for :func:`rotation_between`."""
    return add(add(e, cross(k, e)), scale(sub(scale(k, k_j), scale(e, kk)), d))


@jit()
def slerp(q0: Quat, q1: Quat, t: float) -> Quat:
    """Mirrors :func:`ecs_anim.core.rotations.slerp` for one pair (shorter arc, normalized)."""
    cos_half = q0[0] * q1[0] + q0[1] * q1[1] + q0[2] * q1[2] + q0[3] * q1[3]
    if cos_half < 0.0:
        q1 = (-q1[0], -q1[1], -q1[2], -q1[3])
    cos_half = min(abs(cos_half), 1.0)
    if (1.0 - cos_half) * (1.0 + cos_half) < 1e-12:
        w0, w1 = 1.0 - t, t
    else:
        theta = math.acos(cos_half)
        w0 = math.sin((1.0 - t) * theta)
        w1 = math.sin(t * theta)
    q = (w0 * q0[0] + w1 * q1[0], w0 * q0[1] + w1 * q1[1], w0 * q0[2] + w1 * q1[2],
         w0 * q0[3] + w1 * q1[3])
    n = max(math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]), TINY)
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


@jit()
def nlerp(a: Vec3, b: Vec3, w: float) -> Vec3:
    """Mirrors ``normalize((1 - w) * a + w * b)`` of :func:`ecs_anim.motion.sampling.blend`."""
    v = ((1 - w) * a[0] + w * b[0], (1 - w) * a[1] + w * b[1], (1 - w) * a[2] + w * b[2])
    n = max(math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]), TINY)
    return (v[0] / n, v[1] / n, v[2] / n)


@jit()
def axis_angle(k: Vec3, angle: float) -> Frame:
    """Mirrors :func:`ecs_anim.core.rotations.axis_angle`: the rotation by ``angle`` about the unit axis
    ``k`` (Rodrigues, ``I + sin K + (1 - cos) K K``)."""
    return rotation_about(k, math.sin(angle), math.cos(angle))


@jit()
def rotation_about(k: Vec3, s: float, c: float) -> Frame:
    """The rotation about the unit axis ``k`` whose angle has sine ``s`` and cosine ``c``
    (Rodrigues, ``I + s K + (1 - c) K K``: :func:`axis_angle` after its sine and cosine)."""
    v = 1.0 - c
    # Rows of K = [k]x; K K = (K @ K) element by element.
    k0, k1, k2 = k
    kk00 = -k2 * k2 - k1 * k1
    kk01 = k1 * k0
    kk02 = k2 * k0
    kk10 = k0 * k1
    kk11 = -k2 * k2 - k0 * k0
    kk12 = k2 * k1
    kk20 = k0 * k2
    kk21 = k1 * k2
    kk22 = -k1 * k1 - k0 * k0
    # Columns (x, y, z) of the matrix.
    return ((1.0 + v * kk00, s * k2 + v * kk10, -s * k1 + v * kk20),
            (-s * k2 + v * kk01, 1.0 + v * kk11, s * k0 + v * kk21),
            (s * k1 + v * kk02, -s * k0 + v * kk12, 1.0 + v * kk22))


@jit()
def rotation_toward(a: Vec3, b: Vec3, max_angle: float, weight: float) -> Frame:
    """Mirrors :func:`ecs_anim.solver.steps.rotation_toward`: the smallest rotation taking direction
    ``a`` toward ``b``, ``weight`` of the way and at most ``max_angle``; the identity for a zero
    vector."""
    axis = cross(a, b)
    sin_ab = norm(axis)
    angle = math.atan2(sin_ab, dot(a, b))
    if sin_ab < 1e-12:
        helper = (1.0, 0.0, 0.0) if abs(a[0]) < 0.9 else (0.0, 1.0, 0.0)
        axis = cross(a, helper)
    angle = min(angle * weight, max_angle)
    if norm(a) < 1e-12 or norm(b) < 1e-12:
        angle = 0.0
    return axis_angle(normalize(axis), angle)


@jit()
def axis_angle_of(m: Frame) -> tuple[Vec3, float]:
    """Mirrors ``solver_shell._axis_angle_of``: unit axis and angle of a rotation (below π)."""
    # Element (row i, column j) is m[j][i].
    axis = (m[1][2] - m[2][1], m[2][0] - m[0][2], m[0][1] - m[1][0])
    sin2 = norm(axis)
    cos = m[0][0] + m[1][1] + m[2][2] - 1.0
    return normalize(axis), math.atan2(sin2, cos)


@jit()
def load3(a: F64) -> Vec3:
    """A 3-vector from a 1-D array view of length 3."""
    return (a[0], a[1], a[2])


@jit()
def store3(out: F64, v: Vec3) -> None:
    out[0], out[1], out[2] = v[0], v[1], v[2]


@jit()
def load4(a: F64) -> Quat:
    return (a[0], a[1], a[2], a[3])


@jit()
def store4(out: F64, q: Quat) -> None:
    out[0], out[1], out[2], out[3] = q[0], q[1], q[2], q[3]


@jit()
def load_frame(a: F64) -> Frame:
    """A frame from a (3, 3) array view holding its axes as columns (``a[row, column]``)."""
    return ((a[0, 0], a[1, 0], a[2, 0]), (a[0, 1], a[1, 1], a[2, 1]), (a[0, 2], a[1, 2], a[2, 2]))


@jit()
def store_frame(out: F64, m: Frame) -> None:
    """Write a frame into a (3, 3) array view, axes as columns."""
    for j in range(3):
        for i in range(3):
            out[i, j] = m[j][i]


@jit(inline="always")
def copy_row(dst: F64, c: int, src: F64, i: int) -> None:
    """``dst[c] = src[i]`` element by element, for C-contiguous arrays of the same trailing
    shape (a slice assignment may allocate a temporary, which needs numba's runtime)."""
    to, frm = dst[c].reshape(-1), src[i].reshape(-1)
    for k in range(to.shape[0]):
        to[k] = frm[k]


