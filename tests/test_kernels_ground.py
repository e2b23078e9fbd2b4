"""Compiled ground heights equal the numpy grounds (every kind, and combinations)."""

from dataclasses import dataclass

import numpy as np
import pytest

from ecs_anim.ground import (
    Bumps,
    Combined,
    Ground,
    HeightGrid,
    Plane,
    Slope,
    Stairs,
    describe,
)
from ecs_anim.kernels.ground import height_at


def _grid(seed: int) -> HeightGrid:
    rng = np.random.default_rng(seed)
    return HeightGrid(rng.uniform(-0.2, 0.3, (7, 11)), 0.45, -1.3, 0.7)


GROUNDS = {
    "plane": Plane(0.12),
    "slope": Slope(0.08, -0.05, 0.3),
    "stairs": Stairs(rise_m=0.13, run_m=0.31, steps=5, start_m=0.4, heading_deg=37.0, z_m=0.02),
    "bumps": Bumps(0.04, 2.3, 1.7, -0.01),
    "grid": _grid(3),
    "combined": Combined((Bumps(0.03, 2.5, 3.0), Stairs(0.12, 0.40, 6, 5.0))),
    "nested": Combined((_grid(5), Combined((Slope(0.02, 0.01), _grid(6))), Plane(-0.1))),
}


def _compiled(ground: Ground, xy: np.ndarray) -> np.ndarray:
    d = describe(ground)
    assert d is not None
    return np.array([height_at(x, y, d.kinds, d.params, d.grid) for x, y in xy])


@pytest.mark.parametrize("name", list(GROUNDS))
def test_compiled_height_equals_numpy(name: str) -> None:
    rng = np.random.default_rng(1301)
    ground = GROUNDS[name]
    xy = rng.uniform(-4.0, 9.0, (500, 2))
    np.testing.assert_allclose(_compiled(ground, xy), ground.height(xy), rtol=0, atol=1e-12)


def test_grid_border_and_cell_corners_equal_numpy() -> None:
    ground = _grid(7)
    xs = -1.3 + 0.45 * np.arange(-2, 14)
    ys = 0.7 + 0.45 * np.arange(-2, 10)
    xy = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    np.testing.assert_allclose(_compiled(ground, xy), ground.height(xy), rtol=0, atol=1e-12)


def test_stair_edges_equal_numpy() -> None:
    ground = Stairs(rise_m=0.15, run_m=0.30, steps=8, start_m=1.0)
    x = 1.0 + 0.30 * np.arange(-2, 12)
    xy = np.stack([np.concatenate([x, x - 1e-9, x + 1e-9]), np.zeros(3 * x.size)], -1)
    np.testing.assert_allclose(_compiled(ground, xy), ground.height(xy), rtol=0, atol=1e-12)


@dataclass(frozen=True)
class _Ripples:
    def height(self, xy: np.ndarray) -> np.ndarray:
        return 0.01 * np.cos(xy[..., 0])


def test_a_ground_of_ones_own_has_no_compiled_form() -> None:
    assert describe(_Ripples()) is None
    assert describe(Combined((Plane(), _Ripples()))) is None
