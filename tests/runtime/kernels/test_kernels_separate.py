"""CollisionSeparate's compiled rounds (ecs_anim.runtime.kernels.separate) equal its numpy
methods, the reference: the same scene stepped twice, once each way, ends every tick with the
same postures (1e-9 m) and overlaps.

The bench's walkers overlap each other a tenth of them at a time, free legs, feet down (held by
their ankle) and pairs that may not move among them; the fight's kicks and ward-offs are limbs
held by constraints that aim at the body they overlap, and fold."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import SCENARIOS_DIR
from ecs_anim.core.ground import Bumps, Plane, Slope
from ecs_anim.runtime.bench_scene import BenchScene
from ecs_anim.runtime.simulation import Simulation
from ecs_anim.runtime.system_base import RowGrounds
from ecs_anim.scenario import build_simulation, load_scenario

TOL = 1e-9


def separate_of(sim: Simulation):
    return next(s for s in sim.systems if type(s).__name__ == "CollisionSeparate")


def chains_moved_alike(compiled: Simulation, reference: Simulation, steps: int) -> int:
    """Step both ``steps`` times, the second with the numpy rounds, comparing the postures,
    overlaps and poses after every step; returns how many chains the compiled rounds moved."""
    separate_of(reference).compiled = False
    system = separate_of(compiled)
    rounds = system._separate_compiled
    moved = 0

    def counted(*args):
        nonlocal moved
        rows = rounds(*args)
        moved += rows.size
        return rows

    system._separate_compiled = counted
    for _ in range(steps):
        compiled.step()
        reference.step()
        a, b = compiled.store, reference.store
        np.testing.assert_allclose(a.positions, b.positions, atol=TOL, rtol=0)
        np.testing.assert_allclose(a.overlap_m, b.overlap_m, atol=TOL, rtol=0)
        for name in ("leg_frame", "arm_frame", "leg_fraction", "arm_fraction", "foot_dir",
                     "root_position"):
            np.testing.assert_allclose(getattr(a.poses, name), getattr(b.poses, name),
                                       atol=TOL, rtol=0, err_msg=name)
    return moved


def test_compiled_rounds_match_numpy_on_the_bench_walkers():
    compiled, reference = BenchScene(150, crossing=True).sim, BenchScene(150, crossing=True).sim
    try:
        assert chains_moved_alike(compiled, reference, 8) > 20
    finally:
        compiled.close()
        reference.close()


@pytest.mark.parametrize("name", ["fight_training"])
def test_compiled_rounds_match_numpy_in_the_fight(name):
    scenario = load_scenario(SCENARIOS_DIR / f"{name}.yaml")
    whole_fight = round(scenario.duration_s * scenario.fps)  # steps
    with build_simulation(scenario) as compiled, build_simulation(scenario) as reference:
        assert chains_moved_alike(compiled, reference, whole_fight) > 0


def test_the_ground_of_some_rows_is_the_ground_of_all_rows_taken_at_them():
    """RowGrounds.height_of (the free legs' feet, the moved bodies' soles) answers for a few rows
    what RowGrounds.height answers for every row."""
    rng = np.random.default_rng(3601)
    grounds = RowGrounds([Plane(0.1), Bumps(0.05, 2.0, 3.0), Slope(0.1, -0.2)],
                         rng.integers(0, 3, 50))
    xy = rng.uniform(-5, 5, (50, 2, 2))
    rows = np.array([3, 7, 8, 20, 41, 49])
    np.testing.assert_allclose(grounds.height_of(rows, xy[rows]), grounds.height(xy)[rows],
                               atol=1e-12)
