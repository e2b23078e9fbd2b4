"""Grounds: one interface answering heights for arrays of (x, y) (paper §7: ``height(x, y)``).

Every ground is an immutable specification with a batched :meth:`Ground.height`; nothing loops
over points. Shapes: ``xy`` (..., 2) metres -> heights (...) metres (world Z up).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]


class Ground(Protocol):
    """Anything that answers ground heights for arrays of points."""

    def height(self, xy: F64) -> F64:
        """Heights (...) in metres under points ``xy`` (..., 2)."""
        ...


def _finite(name: str, *values: float) -> None:
    if not all(np.isfinite(v) for v in values):
        raise ValueError(f"{name}: values must be finite, got {values}")


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
            raise ValueError(f"stairs: run_m must be > 0 and steps >= 0, got {self.run_m}, {self.steps}")

    def height(self, xy: F64) -> F64:
        a = np.radians(self.heading_deg)
        along = xy[..., 0] * np.cos(a) + xy[..., 1] * np.sin(a) - self.start_m
        step = np.clip(np.floor(along / self.run_m) + 1.0, 0.0, float(self.steps))
        return self.z_m + self.rise_m * step


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
            raise ValueError("bumps: wavelengths must be > 0")

    def height(self, xy: F64) -> F64:
        return self.z_m + self.amplitude_m * np.sin(2 * np.pi * xy[..., 0] / self.wavelength_x_m) \
            * np.sin(2 * np.pi * xy[..., 1] / self.wavelength_y_m)


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
            raise ValueError(f"height grid: heights must be a 2-D array of at least 2x2 values "
                             f"(rows along y), got shape {h.shape}")
        if not np.all(np.isfinite(h)):
            raise ValueError("height grid: heights must be finite")
        _finite("height grid", self.cell_m, self.origin_x_m, self.origin_y_m)
        if self.cell_m <= 0:
            raise ValueError(f"height grid: cell_m must be > 0, got {self.cell_m}")
        object.__setattr__(self, "_h", h)

    def height(self, xy: F64) -> F64:
        h = self._h
        ny, nx = h.shape
        gx = np.clip((xy[..., 0] - self.origin_x_m) / self.cell_m, 0.0, nx - 1.0)
        gy = np.clip((xy[..., 1] - self.origin_y_m) / self.cell_m, 0.0, ny - 1.0)
        i0 = np.minimum(np.floor(gx).astype(np.int64), nx - 2)
        j0 = np.minimum(np.floor(gy).astype(np.int64), ny - 2)
        u, v = gx - i0, gy - j0
        return ((1 - u) * (1 - v) * h[j0, i0] + u * (1 - v) * h[j0, i0 + 1]
                + (1 - u) * v * h[j0 + 1, i0] + u * v * h[j0 + 1, i0 + 1])


@dataclass(frozen=True)
class Combined:
    """The sum of several grounds (e.g. stairs on a slope, bumps on a grid)."""

    parts: tuple[Ground, ...]

    def height(self, xy: F64) -> F64:
        out = np.zeros(np.shape(xy)[:-1])
        for part in self.parts:
            out = out + part.height(xy)
        return out
