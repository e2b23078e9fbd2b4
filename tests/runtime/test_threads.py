"""Issue 35, item 9: two simulations stepped at once in two threads are independent (6 of 40
such runs diverged or raised): each gives, bit for bit, what it gives alone."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from conftest import MOTIONS_DIR
from ecs_anim import Simulation
from ecs_anim.components import MotionPlayer, Placement
from ecs_anim.core.morphology import Morphology
from ecs_anim.io.importing import import_bvh
from ecs_anim.motion.constraints import Activation

TICKS = 60


@pytest.fixture(scope="module")
def walk():
    return import_bvh(MOTIONS_DIR / "walk.bvh")


def _crowd(walk, n: int) -> Simulation:
    """``n`` walkers of different sizes, each reaching with its trunk in the chain (every
    system of the tick has work)."""
    sim = Simulation({"walk": walk})
    for i in range(n):
        e = sim.spawn(f"c{i}", Morphology.from_stature(1.2 + 0.1 * i), MotionPlayer("walk"),
                      Placement((0.0, 2.0 * i)))
        sim.add_constraint(e, "reach", "wrist_r", 5, Activation(0.5, 100.0, 0.3, 0.0),
                           (1.0, 2.0 * i - 0.3, 1.2), chain=("arm_r", "trunk"))
    return sim


def _played(sim: Simulation, out: dict[int, object], key: int) -> None:
    try:
        for _ in range(TICKS):
            sim.step()
        out[key] = sim.store.positions.copy()
    except Exception as exc:  # the thread's outcome, asserted by the test
        out[key] = exc


def test_two_simulations_in_two_threads_are_independent(walk):
    alone: dict[int, object] = {}
    _played(_crowd(walk, 8), alone, 0)
    _played(_crowd(walk, 3), alone, 1)
    for _ in range(5):
        together: dict[int, object] = {}
        threads = [threading.Thread(target=_played, args=(_crowd(walk, n), together, k))
                   for k, n in enumerate((8, 3))]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(timeout=120)
        for k in (0, 1):
            assert isinstance(together[k], np.ndarray), together[k]
            np.testing.assert_array_equal(together[k], alone[k])
