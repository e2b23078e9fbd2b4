"""What every system shares: access to the simulation's store, clips and ground, and timing."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import esper

if TYPE_CHECKING:
    from .simulation import Simulation


class System(esper.Processor):
    """An esper processor bound to one simulation. Subclasses implement :meth:`run`.

    ``seconds`` accumulates the wall time spent in :meth:`run` (for reports and the benchmark).
    """

    def __init__(self, sim: Simulation):
        super().__init__()
        self.sim = sim
        self.seconds = 0.0
        self.ticks = 0

    def process(self, dt: float) -> None:  # type: ignore[override]
        start = time.perf_counter()
        if self.sim.store.n:
            self.run(dt)
        self.seconds += time.perf_counter() - start
        self.ticks += 1

    def run(self, dt: float) -> None:
        raise NotImplementedError
