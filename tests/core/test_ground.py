"""Grounds answer batched heights; each shape is checked at known points."""

import numpy as np
import pytest

from ecs_anim.core.ground import Bumps, Combined, HeightGrid, Plane, Slope, Stairs


def test_plane_and_slope():
    xy = np.array([[0.0, 0.0], [2.0, -1.0]])
    np.testing.assert_allclose(Plane(0.3).height(xy), [0.3, 0.3])
    np.testing.assert_allclose(Slope(0.1, -0.2, 1.0).height(xy), [1.0, 1.0 + 0.2 + 0.2])


def test_stairs_steps_and_heading():
    s = Stairs(rise_m=0.15, run_m=0.3, steps=3, start_m=1.0)
    x = np.array([0.99, 1.0, 1.29, 1.31, 1.61, 1.91, 5.0])
    h = s.height(np.stack([x, np.zeros_like(x)], axis=-1))
    np.testing.assert_allclose(h, [0.0, 0.15, 0.15, 0.30, 0.45, 0.45, 0.45])
    turned = Stairs(rise_m=0.15, run_m=0.3, steps=3, start_m=1.0, heading_deg=90.0)
    assert turned.height(np.array([0.0, 1.31])) == pytest.approx(0.30)


def test_bumps_and_grid_bilinear():
    b = Bumps(0.05, 2.0, 2.0)
    assert b.height(np.array([0.5, 0.5])) == pytest.approx(0.05)
    g = HeightGrid(np.array([[0.0, 1.0], [2.0, 3.0]]), cell_m=1.0)
    np.testing.assert_allclose(g.height(np.array([[0.5, 0.5], [1.0, 0.0], [-5.0, 9.0]])), [1.5, 1.0, 2.0])
    c = Combined((Plane(0.1), g))
    assert c.height(np.array([0.5, 0.5])) == pytest.approx(1.6)


def test_grid_of_wrong_shape_or_nan_is_refused():
    with pytest.raises(ValueError, match="2-D"):
        HeightGrid(np.zeros(5), cell_m=1.0)
    with pytest.raises(ValueError, match="finite"):
        HeightGrid(np.array([[0.0, np.nan], [0.0, 0.0]]), cell_m=1.0)
    with pytest.raises(ValueError, match="run_m"):
        Stairs(run_m=0.0)
