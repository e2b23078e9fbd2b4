"""What every system shares: the simulation's store, clips and ground; its rows; its declared
reads and writes; timing.

Rows (DESIGN §7b): a system's :attr:`System.query` names the components a character needs for
the system to process it (beyond :class:`~ecs_anim.components.CharacterRow`, which every
character has). :meth:`System.rows` is the sorted int64 array of store rows of those characters,
from an esper query made once per structural change (a character spawned or removed, a component
added, replaced or removed: ``Simulation.structure_version``), never per tick. A kernel iterates
exactly ``rows`` (``for k in range(lo, hi): c = rows[k]``, a chunk per thread); a numpy system
indexes with it, or uses the whole arrays when :meth:`System.all_rows` says every character is
in. :meth:`System.ground_groups` splits the rows by the ground each stands on (its own
GroundQuery, or the environment's); :meth:`System.row_ground` is the same as one ground for
numpy code over all rows.

Declarations (STYLE 5, Bevy's system parameters): ``reads`` and ``writes`` are tuples of store
field names (``"poses"``, ``"contact_weight"``; ``"constraints.weight"`` for a column of the
constraint table), in the order of the system's docstring. ``tests/ecs/test_ecs.py`` derives each
field's ordered writers from ``SCHEDULE`` and checks them. ``on_structure_change`` are functions
of the simulation run once, before :meth:`System.run`, on the first tick after a structural
change (MorphologyAdapt takes replaced bodies into the store that way).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, ClassVar

import esper
import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from ecs_anim.core.ground import Ground
    from ecs_anim.runtime.simulation import Simulation

I64 = NDArray[np.int64]


class System(esper.Processor):
    """An esper processor bound to one simulation. Subclasses implement :meth:`run`.

    ``seconds`` accumulates the wall time spent in :meth:`run` (for reports and the benchmark),
    ``cpu_seconds`` the process's CPU time (every thread's; the frame budget's clock),
    ``last_cpu_seconds`` that of the last run alone.
    """

    #: Components (beyond CharacterRow) a character needs to be in this system's rows.
    query: ClassVar[tuple[type, ...]] = ()
    #: Store fields this system reads / writes (see the module docstring).
    reads: ClassVar[tuple[str, ...]] = ()
    writes: ClassVar[tuple[str, ...]] = ()
    #: Run once before :meth:`run` on the first tick after a structural change.
    on_structure_change: ClassVar[tuple[Callable[[Simulation], None], ...]] = ()
    #: Run even when the simulation has no character (the clock and time triggers go on).
    runs_without_characters: ClassVar[bool] = False
    #: Processes only the rows due this tick under the frame budget's update rate
    #: (:mod:`ecs_anim.runtime.update_rate`; its CPU time is the rate's model of an update).
    follows_update_rate: ClassVar[bool] = False

    def __init__(self, sim: Simulation):
        super().__init__()
        self.sim = sim
        self.seconds = 0.0
        self.cpu_seconds = 0.0
        self.last_cpu_seconds = 0.0
        self.ticks = 0
        self._rows_version = -1
        self._rows: I64 = np.zeros(0, np.int64)
        self._groups_version = -1
        self._groups: list[tuple[Ground, I64]] = []
        self._hooks_version = -1
        self._row_ground_version = -1
        self._row_ground: RowGrounds

    def process(self, dt: float) -> None:
        start, cpu_start = time.perf_counter(), time.process_time()
        if self.sim.store.n or self.runs_without_characters:
            if self._hooks_version != self.sim.structure_version:
                self._hooks_version = self.sim.structure_version
                for hook in type(self).on_structure_change:
                    hook(self.sim)
            self.run(dt)
        self.seconds += time.perf_counter() - start
        self.last_cpu_seconds = time.process_time() - cpu_start
        self.cpu_seconds += self.last_cpu_seconds
        self.ticks += 1

    def rows(self) -> I64:
        """(r,) int64 sorted store rows of the characters having every component of
        :attr:`query`; the same array object until the simulation's structure changes."""
        version = self.sim.structure_version
        if self._rows_version != version:
            self._rows = self.sim.rows_with(*self.query)
            self._rows.setflags(write=False)
            self._rows_version = version
        return self._rows

    def in_rows(self) -> NDArray[np.bool_]:
        """(n,) bool: which store rows are in :meth:`rows` (for masks over whole arrays)."""
        mask = np.zeros(self.sim.store.n, bool)
        mask[self.rows()] = True
        return mask

    def all_rows(self) -> bool:
        """Whether :meth:`rows` is every character (0..n-1): whole arrays can be used."""
        return int(self.rows().shape[0]) == self.sim.store.n

    def ground_groups(self) -> list[tuple[Ground, I64]]:
        """:meth:`rows` split by ground: ``[(ground, rows standing on it), ...]``, the
        environment's ground first (``store.ground_index`` 0, ``sim.grounds[0]``), groups
        without rows left out. Cached like :meth:`rows`."""
        version = self.sim.structure_version
        if self._groups_version != version:
            rows = self.rows()
            index = self.sim.store.ground_index[rows]
            self._groups = [(ground, rows[index == k]) for k, ground in enumerate(self.sim.grounds)
                            if np.any(index == k)]
            self._groups_version = version
        return self._groups

    def row_ground(self) -> RowGrounds:
        """The ground under each character as one ground for arrays over all store rows
        (leading axis n): each row's points answered by its own ground. Cached like
        :meth:`rows`."""
        version = self.sim.structure_version
        if self._row_ground_version != version:
            self._row_ground = RowGrounds(self.sim.grounds, self.sim.store.ground_index.copy())
            self._row_ground_version = version
        return self._row_ground

    def run(self, dt: float) -> None:
        raise NotImplementedError


class RowGrounds:
    """Every character's ground (``grounds[index[row]]``) answering as one: :meth:`height` of
    points ``xy`` (n, ..., 2) whose leading axis is the store's rows gives (n, ...) metres, each
    row from its own ground; with one ground in use it is that ground's own call."""

    def __init__(self, grounds: list[Ground], index: I64):
        used = np.unique(index)
        self.groups = [(grounds[int(k)], np.flatnonzero(index == k)) for k in used]
        self.n = int(index.shape[0])
        self.used, self.index = used, index

    def height(self, xy: NDArray[np.float64]) -> NDArray[np.float64]:
        if len(self.groups) <= 1:
            return self.groups[0][0].height(xy) if self.groups else np.zeros(xy.shape[:-1])
        assert xy.shape[0] == self.n, "a RowGrounds answers arrays over every store row"
        out = np.empty(xy.shape[:-1])
        for ground, rows in self.groups:
            out[rows] = ground.height(xy[rows])
        return out

    def height_of(self, rows: I64, xy: NDArray[np.float64]) -> NDArray[np.float64]:
        """As :meth:`height`, for the store ``rows`` (k,) only: ``xy`` (k, ..., 2) -> (k, ...)
        metres (the ground asked about those points alone)."""
        if len(self.groups) <= 1:
            return self.height(xy)
        out = np.empty(xy.shape[:-1])
        index = self.index[rows]
        for key, (ground, _) in zip(self.used, self.groups, strict=True):
            mine = index == key
            out[mine] = ground.height(xy[mine])
        return out

