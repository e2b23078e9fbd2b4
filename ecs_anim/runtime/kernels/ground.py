"""Compiled ground heights: every built-in ground of :mod:`ecs_anim.core.ground` as arrays.

A ground is passed to a kernel as the three arrays of its
:class:`~ecs_anim.core.ground.GroundDescription` (``kinds``, ``params``, ``grid``; see
:func:`ecs_anim.core.ground.describe`), and :func:`height_at` answers one point. A ground of the
user's own (any object with ``height(xy)``) has no description: its callers keep numpy.

Kind codes are written here as literals (numba's cache keys on this file's source, not on
:mod:`ecs_anim.core.ground`'s); an import-time check pins them. Kernels that branch on a
ground's kind use these names.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core import ground as _ground
from ecs_anim.runtime.kernels.vec import F64, jit

#: The kind codes of :class:`~ecs_anim.core.ground.GroundDescription`'s ``kinds``.
PLANE, SLOPE, STAIRS, BUMPS, HEIGHT_GRID = 0, 1, 2, 3, 4
assert (_ground.PLANE, _ground.SLOPE, _ground.STAIRS, _ground.BUMPS, _ground.HEIGHT_GRID) \
    == (PLANE, SLOPE, STAIRS, BUMPS, HEIGHT_GRID)

I64 = NDArray[np.int64]
#: A ground part's parameters (N_GROUND_PARAMS of :mod:`ecs_anim.core.ground`).
GroundParams = tuple[float, float, float, float, float, float, float]
assert _ground.N_GROUND_PARAMS == 7


@jit()
def grid_height(x: float, y: float, p: F64, grid: F64) -> float:
    """Mirrors :meth:`ecs_anim.core.ground.HeightGrid.height` at one point (``p`` its parameters)."""
    offset, nx, ny = int(p[0]), int(p[1]), int(p[2])
    cell, origin_x, origin_y = p[3], p[4], p[5]
    gx = min(max((x - origin_x) / cell, 0.0), nx - 1.0)
    gy = min(max((y - origin_y) / cell, 0.0), ny - 1.0)
    i0 = min(math.floor(gx), nx - 2)
    j0 = min(math.floor(gy), ny - 2)
    u, v = gx - i0, gy - j0
    k = offset + j0 * nx + i0
    return float((1 - u) * (1 - v) * grid[k] + u * (1 - v) * grid[k + 1]
                 + (1 - u) * v * grid[k + nx] + u * v * grid[k + nx + 1])


# sine: fdlibm's (FreeBSD's e_rem_pio2.c reduction by pi/2 in three parts, k_sin.c, k_cos.c),
# written without branches so that a loop of it runs on the vector units (numba here has no
# vector math library: math.sin is a call to the C library's, one point at a time).
# Not .lanes.sin_quarter (a Taylor series for |x| <= pi/2, the slerp's): the bumps' arguments
# are any size, and either one in the other's place would change results' bits.
# fdlibm's notice, which its licence asks a derived work to keep:
#   Copyright (C) 1993 by Sun Microsystems, Inc. All rights reserved.
#   Developed at SunSoft, a Sun Microsystems, Inc. business.
#   Permission to use, copy, modify, and distribute this software is freely granted,
#   provided that this notice is preserved.
_INV_PIO2 = 6.36619772367581382433e-01
_PIO2_1, _PIO2_1T = 1.57079632673412561417e+00, 6.07710050650619224932e-11
_PIO2_2, _PIO2_2T = 6.07710050630396597660e-11, 2.02226624879595063154e-21
_PIO2_3, _PIO2_3T = 2.02226624871116645580e-21, 8.47842766036889956997e-32
_S1, _S2, _S3 = -1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04
_S4, _S5, _S6 = 2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10
_C1, _C2, _C3 = 4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05
_C4, _C5, _C6 = -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11
#: 1.5 * 2**52: ``(a + it) - it`` is ``a`` rounded to an integer (|a| < 2**51).
_ROUND = 6755399441055744.0
#: :func:`sine`'s arguments (rad) are under this: n pi/2 taken off exactly (n * _PIO2_1, 33 bits
#: times at most 20, is a double). Bumps 2.5 m long reach it 400 km out.
SINE_DOMAIN = 2.0**20


@jit(inline="always")
def sine(x: float) -> float:
    """sin(x) for |x| < :data:`SINE_DOMAIN` rad, within 1 ulp of the C library's (its bits for
    85-90 % of x); NaN for NaN."""
    n = (x * _INV_PIO2 + _ROUND) - _ROUND  # x = n pi/2 + (y0 + y1)
    r = x - n * _PIO2_1
    t, w = r, n * _PIO2_2
    r = t - w
    w = n * _PIO2_2T - ((t - r) - w)
    t, w = r, n * _PIO2_3
    r = t - w
    w = n * _PIO2_3T - ((t - r) - w)
    y0 = r - w
    y1 = (r - y0) - w
    z = y0 * y0
    z2 = z * z
    rs = _S2 + z * (_S3 + z * _S4) + z * z2 * (_S5 + z * _S6)
    sin_y = y0 - ((z * (0.5 * y1 - z * y0 * rs) - y1) - z * y0 * _S1)
    rc = z * (_C1 + z * (_C2 + z * _C3)) + z2 * z2 * (_C4 + z * (_C5 + z * _C6))
    hz = 0.5 * z
    wc = 1.0 - hz
    cos_y = wc + (((1.0 - wc) - hz) + (z * rc - y0 * y1))
    quadrant = n - 4.0 * np.floor(0.25 * n)  # n mod 4, as a float: no integer conversion
    out = cos_y if quadrant == 1.0 or quadrant == 3.0 else sin_y
    return -out if quadrant >= 2.0 else out


@jit(inline="always")
def bumps_height(x: float, y: float, z: float, amplitude: float, kx: float, ky: float) -> float:
    """:class:`~ecs_anim.core.ground.Bumps`' height at (``x``, ``y``) (m), where ``kx * x`` and
    ``ky * y`` are within :data:`SINE_DOMAIN` (:func:`bumps_in_domain`): ``kx``, ``ky`` its
    wavenumbers (rad/m), ``z`` its base and ``amplitude`` (m)."""
    return z + amplitude * sine(kx * x) * sine(ky * y)


@jit(inline="always")
def bumps_in_domain(x: float, y: float, kx: float, ky: float) -> bool:
    """Whether :func:`bumps_height` answers (``x``, ``y``) (else: the C library's sines)."""
    return abs(kx * x) < SINE_DOMAIN and abs(ky * y) < SINE_DOMAIN


@jit()
def part_height(kind: int, x: float, y: float, p: GroundParams) -> float:
    """Mirrors the ``height`` of :class:`~ecs_anim.core.ground.Plane`, ``Slope``, ``Stairs`` or
    ``Bumps`` (by ``kind``) at one point (m); ``p`` the part's parameters."""
    if kind == PLANE:
        return float(p[0])
    if kind == SLOPE:
        return float(p[0] + p[1] * x + p[2] * y)
    if kind == STAIRS:
        along = x * p[5] + y * p[6] - p[4]
        step = min(max(math.floor(along / p[2]) + 1.0, 0.0), p[3])
        return float(p[0] + p[1] * step)
    if bumps_in_domain(x, y, p[2], p[3]):  # p[2:4]: wavenumbers
        return bumps_height(x, y, p[0], p[1], p[2], p[3])
    return float(p[0] + p[1] * math.sin(p[2] * x) * math.sin(p[3] * y))


# Inlined: small, and ground adaptation asks it about ten times a character.
@jit(inline="always")
def height_at(x: float, y: float, kinds: I64, params: F64, grid: F64) -> float:
    """Mirrors ``ground.height`` of a built-in ground (:class:`~ecs_anim.core.ground.Combined`: the
    sum of its parts) at the point (``x``, ``y``) metres; the ground as described by
    :func:`ecs_anim.core.ground.describe` (``kinds`` (parts,), ``params`` (parts, N_GROUND_PARAMS),
    ``grid`` the height grids' values). Returns metres."""
    out = 0.0
    for k in range(kinds.shape[0]):
        if kinds[k] == HEIGHT_GRID:
            out = out + grid_height(x, y, params[k], grid)
        else:
            out = out + part_height(kinds[k], x, y, (params[k, 0], params[k, 1], params[k, 2],
                                                     params[k, 3], params[k, 4], params[k, 5],
                                                     params[k, 6]))
    return out


#: A point this close (m, in x and in y) to one whose height is already known takes that height
#: on a smooth ground (:func:`smooth`): they differ by at most its grade times this, far under
#: the 1e-9 m the kernels keep to their numpy references. The ground adaptation's points
#: decoded onto a target they reached land this close to it (rounding: 1e-15 m).
NEAR_M = 1e-10


@jit(inline="always")
def smooth(kinds: I64) -> bool:
    """Whether a described ground has no step or kink: planes, slopes and bumps only (a height
    grid's cell borders and a stairs' risers change heights or grades at once)."""
    for k in range(kinds.shape[0]):
        if kinds[k] != PLANE and kinds[k] != SLOPE and kinds[k] != BUMPS:
            return False
    return True


@jit(inline="always")
def near_known(x: float, y: float, known: tuple[float, float, float], is_smooth: bool) -> bool:
    """Whether the height ``known`` (x, y, height; NaN: none) answers the point (``x``, ``y``)
    (m): within :data:`NEAR_M` of it on a smooth ground (``is_smooth``: :func:`smooth`)."""
    return is_smooth and abs(x - known[0]) <= NEAR_M and abs(y - known[1]) <= NEAR_M


@jit(inline="always")
def height_near(x: float, y: float, known: tuple[float, float, float], is_smooth: bool,
                kinds: I64, params: F64, grid: F64) -> float:
    """:func:`height_at` (``x``, ``y``), or the height ``known`` (x, y, height; NaN: none) of a
    point within :data:`NEAR_M` of it on a smooth ground (``is_smooth``: :func:`smooth`), without
    asking the ground again. Metres."""
    if near_known(x, y, known, is_smooth):
        return known[2]
    return height_at(x, y, kinds, params, grid)
