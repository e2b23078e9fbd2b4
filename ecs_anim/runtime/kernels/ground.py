"""Compiled ground heights: every built-in ground of :mod:`ecs_anim.core.ground` as arrays.

A ground is passed to a kernel as the three arrays of its
:class:`~ecs_anim.core.ground.GroundDescription` (``kinds``, ``params``, ``grid``; see
:func:`ecs_anim.core.ground.describe`), and :func:`height_at` answers one point. A ground of the
user's own (any object with ``height(xy)``) has no description: its callers keep numpy.

Kind codes are written here as literals (numba's cache keys on this file's source, not on
:mod:`ecs_anim.core.ground`'s); an import-time check pins them.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core import ground as _ground
from ecs_anim.runtime.kernels.vec import F64, jit

_PLANE, _SLOPE, _STAIRS, _BUMPS, _HEIGHT_GRID = 0, 1, 2, 3, 4
assert (_ground.PLANE, _ground.SLOPE, _ground.STAIRS, _ground.BUMPS, _ground.HEIGHT_GRID) \
    == (_PLANE, _SLOPE, _STAIRS, _BUMPS, _HEIGHT_GRID)

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


@jit()
def part_height(kind: int, x: float, y: float, p: GroundParams) -> float:
    """Mirrors the ``height`` of :class:`~ecs_anim.core.ground.Plane`, ``Slope``, ``Stairs`` or
    ``Bumps`` (by ``kind``) at one point (m); ``p`` the part's parameters."""
    if kind == _PLANE:
        return float(p[0])
    if kind == _SLOPE:
        return float(p[0] + p[1] * x + p[2] * y)
    if kind == _STAIRS:
        along = x * p[5] + y * p[6] - p[4]
        step = min(max(math.floor(along / p[2]) + 1.0, 0.0), p[3])
        return float(p[0] + p[1] * step)
    return float(p[0] + p[1] * math.sin(p[2] * x) * math.sin(p[3] * y))  # p[2:4]: wavenumbers


# Inlined: small, and ground adaptation asks it about ten times a character.
@jit(inline="always")
def height_at(x: float, y: float, kinds: I64, params: F64, grid: F64) -> float:
    """Mirrors ``ground.height`` of a built-in ground (:class:`~ecs_anim.core.ground.Combined`: the
    sum of its parts) at the point (``x``, ``y``) metres; the ground as described by
    :func:`ecs_anim.core.ground.describe` (``kinds`` (parts,), ``params`` (parts, N_GROUND_PARAMS),
    ``grid`` the height grids' values). Returns metres."""
    out = 0.0
    for k in range(kinds.shape[0]):
        if kinds[k] == _HEIGHT_GRID:
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
        if kinds[k] != _PLANE and kinds[k] != _SLOPE and kinds[k] != _BUMPS:
            return False
    return True


@jit(inline="always")
def height_near(x: float, y: float, known: tuple[float, float, float], is_smooth: bool,
                kinds: I64, params: F64, grid: F64) -> float:
    """:func:`height_at` (``x``, ``y``), or the height ``known`` (x, y, height; NaN: none) of a
    point within :data:`NEAR_M` of it on a smooth ground (``is_smooth``: :func:`smooth`), without
    asking the ground again. Metres."""
    if is_smooth and abs(x - known[0]) <= NEAR_M and abs(y - known[1]) <= NEAR_M:
        return known[2]
    return height_at(x, y, kinds, params, grid)
