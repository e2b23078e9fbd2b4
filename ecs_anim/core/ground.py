"""Grounds: one interface answering heights for arrays of (x, y) (paper §7: ``height(x, y)``).

Every ground is an immutable specification with a batched :meth:`Ground.height`; nothing loops
over points. Shapes: ``xy`` (..., 2) metres -> heights (...) metres (world Z up).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import UsageError

F64 = NDArray[np.float64]

#: Kind codes of a ground part in a :class:`GroundDescription`.
PLANE, SLOPE, STAIRS, BUMPS, HEIGHT_GRID = 0, 1, 2, 3, 4
#: Parameters per part (unused ones are zero); what each holds is given by its kind:
#: plane (z), slope (z, grade_x, grade_y), stairs (z, rise, run, steps, start, cos, sin of the
#: heading), bumps (z, amplitude, the wavenumbers 2π/λx, 2π/λy), height grid (offset of its values
#: in ``grid``, nx, ny, cell, origin_x, origin_y).
N_GROUND_PARAMS = 7


class Ground(Protocol):
    """Anything that answers ground heights for arrays of points."""

    def height(self, xy: F64) -> F64:
        """Heights (...) in metres under points ``xy`` (..., 2)."""
        ...


def _finite(name: str, *values: float) -> None:
    if not all(np.isfinite(v) for v in values):
        raise UsageError(f"{name}: values must be finite, got {values}")


@dataclass(frozen=True)
class Plane:
    """A horizontal plane at ``z_m``."""

    z_m: float = 0.0

    def __post_init__(self) -> None:
        _finite("plane", self.z_m)

    def height(self, xy: F64) -> F64:
        return np.full(np.shape(xy)[:-1], self.z_m)


@dataclass(frozen=True)
class Slope:
    """A tilted plane ``z = z_m + grade_x * x + grade_y * y`` (grades are rise over run)."""

    grade_x: float = 0.0
    grade_y: float = 0.0
    z_m: float = 0.0

    def __post_init__(self) -> None:
        _finite("slope", self.grade_x, self.grade_y, self.z_m)

    def height(self, xy: F64) -> F64:
        return self.z_m + self.grade_x * xy[..., 0] + self.grade_y * xy[..., 1]


@dataclass(frozen=True)
class Stairs:
    """Steps going up along a horizontal direction: flat before ``start_m``, then each step of
    ``run_m`` depth rises by ``rise_m``, for ``steps`` steps (then flat at the top).

    ``heading_deg`` is the direction of ascent, anticlockwise from +x.
    """

    rise_m: float = 0.15
    run_m: float = 0.30
    steps: int = 8
    start_m: float = 1.0
    heading_deg: float = 0.0
    z_m: float = 0.0

    def __post_init__(self) -> None:
        _finite("stairs", self.rise_m, self.run_m, self.start_m, self.heading_deg, self.z_m)
        if self.run_m <= 0 or self.steps < 0:
            raise UsageError(f"stairs: run_m must be > 0 and steps >= 0, got {self.run_m}, {self.steps}")

    def height(self, xy: F64) -> F64:
        a = np.radians(self.heading_deg)
        along = xy[..., 0] * np.cos(a) + xy[..., 1] * np.sin(a) - self.start_m
        step = np.clip(np.floor(along / self.run_m) + 1.0, 0.0, float(self.steps))
        height: F64 = self.z_m + self.rise_m * step
        return height


@dataclass(frozen=True)
class Bumps:
    """Smooth sinusoidal bumps ``z = z_m + amplitude * sin(2πx/λx) * sin(2πy/λy)``."""

    amplitude_m: float = 0.05
    wavelength_x_m: float = 2.0
    wavelength_y_m: float = 2.0
    z_m: float = 0.0

    def __post_init__(self) -> None:
        _finite("bumps", self.amplitude_m, self.wavelength_x_m, self.wavelength_y_m, self.z_m)
        if self.wavelength_x_m <= 0 or self.wavelength_y_m <= 0:
            raise UsageError("bumps: wavelengths must be > 0")

    @property
    def _wavenumbers(self) -> tuple[float, float]:
        """(2π/λx, 2π/λy) rad/m: the sines' arguments are these times x and y (a product: no
        division at each point, here as in the compiled query)."""
        return 2 * np.pi / self.wavelength_x_m, 2 * np.pi / self.wavelength_y_m

    def height(self, xy: F64) -> F64:
        kx, ky = self._wavenumbers
        return self.z_m + self.amplitude_m * np.sin(kx * xy[..., 0]) * np.sin(ky * xy[..., 1])


@dataclass(frozen=True)
class HeightGrid:
    """Heights sampled on a regular grid, bilinear in between, clamped at the border.

    ``heights_m`` (ny, nx): row ``j`` at ``y = origin_y + j * cell_m``, column ``i`` at
    ``x = origin_x + i * cell_m``.
    """

    heights_m: F64
    cell_m: float
    origin_x_m: float = 0.0
    origin_y_m: float = 0.0
    _h: F64 = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        h = np.asarray(self.heights_m, dtype=np.float64)
        if h.ndim != 2 or h.shape[0] < 2 or h.shape[1] < 2:
            raise UsageError(f"height grid: heights must be a 2-D array of at least 2x2 values "
                             f"(rows along y), got shape {h.shape}")
        if not np.all(np.isfinite(h)):
            raise UsageError("height grid: heights must be finite")
        _finite("height grid", self.cell_m, self.origin_x_m, self.origin_y_m)
        if self.cell_m <= 0:
            raise UsageError(f"height grid: cell_m must be > 0, got {self.cell_m}")
        object.__setattr__(self, "_h", h)

    def height(self, xy: F64) -> F64:
        h = self._h
        ny, nx = h.shape
        gx = np.clip((xy[..., 0] - self.origin_x_m) / self.cell_m, 0.0, nx - 1.0)
        gy = np.clip((xy[..., 1] - self.origin_y_m) / self.cell_m, 0.0, ny - 1.0)
        i0 = np.minimum(np.floor(gx).astype(np.int64), nx - 2)
        j0 = np.minimum(np.floor(gy).astype(np.int64), ny - 2)
        u, v = gx - i0, gy - j0
        height: F64 = ((1 - u) * (1 - v) * h[j0, i0] + u * (1 - v) * h[j0, i0 + 1]
                       + (1 - u) * v * h[j0 + 1, i0] + u * v * h[j0 + 1, i0 + 1])
        return height


@dataclass(frozen=True)
class Combined:
    """The sum of several grounds (e.g. stairs on a slope, bumps on a grid)."""

    parts: tuple[Ground, ...]

    def height(self, xy: F64) -> F64:
        out = np.zeros(np.shape(xy)[:-1])
        for part in self.parts:
            out = out + part.height(xy)
        return out


@dataclass(frozen=True)
class GroundDescription:
    """A built-in ground as arrays, for :func:`ecs_anim.runtime.kernels.ground.height_at`: the sum of
    its parts (one part unless the ground is :class:`Combined`).

    kinds : (parts,) int64 kind codes (:data:`PLANE` ...); params : (parts, N_GROUND_PARAMS);
    grid : every height grid's heights (metres), rows along y, flattened and concatenated.
    """

    kinds: NDArray[np.int64]
    params: F64
    grid: F64


def _parts(ground: Ground, grids: list[F64]) -> list[list[float]] | None:
    """``[kind, *params]`` of each part of ``ground`` (None: not a built-in ground); a height
    grid's heights are appended to ``grids``."""
    if isinstance(ground, Plane):
        return [[PLANE, ground.z_m]]
    if isinstance(ground, Slope):
        return [[SLOPE, ground.z_m, ground.grade_x, ground.grade_y]]
    if isinstance(ground, Stairs):
        a = np.radians(ground.heading_deg)
        return [[STAIRS, ground.z_m, ground.rise_m, ground.run_m, float(ground.steps),
                 ground.start_m, float(np.cos(a)), float(np.sin(a))]]
    if isinstance(ground, Bumps):
        return [[BUMPS, ground.z_m, ground.amplitude_m, *ground._wavenumbers]]
    if isinstance(ground, HeightGrid):
        h = ground._h
        offset = sum(g.size for g in grids)
        grids.append(h.ravel())
        return [[HEIGHT_GRID, float(offset), float(h.shape[1]), float(h.shape[0]), ground.cell_m,
                 ground.origin_x_m, ground.origin_y_m]]
    if isinstance(ground, Combined):
        out: list[list[float]] = []
        for part in ground.parts:
            sub = _parts(part, grids)
            if sub is None:
                return None
            out.extend(sub)
        return out
    return None


def built_in(ground: Ground) -> bool:
    """Whether ``ground`` is built in (made of the grounds the compiled kernels know:
    :func:`describe` gives it a description), not a ground of the user's own."""
    return _parts(ground, []) is not None


def describe(ground: Ground) -> GroundDescription | None:
    """The compiled description of a built-in ground (nested :class:`Combined` flattened into
    its parts); None for any other :class:`Ground` (it has only its numpy ``height``)."""
    grids: list[F64] = []
    parts = _parts(ground, grids)
    if parts is None:
        return None
    params = np.zeros((len(parts), N_GROUND_PARAMS))
    for k, p in enumerate(parts):
        params[k, :len(p) - 1] = p[1:]
    kinds = np.array([p[0] for p in parts], dtype=np.int64)
    grid = np.concatenate(grids) if grids else np.zeros(1)
    return GroundDescription(kinds, params, np.ascontiguousarray(grid, dtype=np.float64))


def sheerest(ground: Ground) -> tuple[float, float]:
    """(the tallest rise a step meets on ``ground`` (m), its steepest grade (rise over run)),
    an upper bound from its parts, summed where :class:`Combined` adds them: a stairs' riser, a
    height grid's largest difference between neighbouring cells (and as a grade over its cell),
    a slope's grade, bumps' steepest flank (``2π amplitude / wavelength``); (0, 0) for a plane
    or a ground that is not built in (only its heights are known)."""
    if isinstance(ground, Stairs):
        return abs(ground.rise_m), 0.0
    if isinstance(ground, Slope):
        return 0.0, float(np.hypot(ground.grade_x, ground.grade_y))
    if isinstance(ground, Bumps):
        shortest = min(ground.wavelength_x_m, ground.wavelength_y_m)
        return 0.0, float(2 * np.pi * abs(ground.amplitude_m) / shortest)
    if isinstance(ground, HeightGrid):
        h = np.asarray(ground.heights_m)
        step = max(float(np.abs(np.diff(h, axis=0)).max()), float(np.abs(np.diff(h, axis=1)).max()))
        return step, step / ground.cell_m
    if isinstance(ground, Combined):
        parts = [sheerest(part) for part in ground.parts]
        return sum(p[0] for p in parts), sum(p[1] for p in parts)
    return 0.0, 0.0
