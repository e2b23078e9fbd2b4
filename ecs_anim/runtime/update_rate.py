"""The frame budget's last resort: characters played, grounded and posed every 2nd, 4th or 8th tick.

When the frame budget (``SolverSettings.budget_ms``, :mod:`ecs_anim.solver.budget`) has
dropped every character's constraints and the tick still does not fit, what is left are the
systems it does not cut (MotionPlayback, GroundAdapt, PostureConvert: those whose
:attr:`System.follows_update_rate` is set: 20 of its 24-27 ms at 19,000). This is
their level of detail (the update rate optimisation of game engines): the characters furthest from the
focus (``SolverSettings.focus_in_world``; without one, the later rows) are played, grounded and
posed every :data:`UPDATE_INTERVALS` tick only, the most that fit every tick, twice as many
after them every 2nd, four times as many every 4th, the rest every 8th (the tiers of
:func:`~ecs_anim.solver.budget.solve_intervals`). Between two updates a character keeps its
last posture (its clock runs on: the next update samples the motion where it is then, its
planted feet on the same footprints), and CollisionSeparate still pushes it; its events
(contacts begun) are seen at its next update. Its ground follows over the ticks since its last
update (:meth:`UpdateRate.due_groups`), and a rise too tall stops it as it stops the others
(:meth:`UpdateRate.elapsed_ticks`). Arrays a tick makes anew (joint rotations or vertebrae
switched on: a recorder started) are filled for every character on that tick.

Decided once a tick, before MotionPlayback, from a model of the tick measured as the frame
budget's is (each system's CPU time, per kernel thread, smoothed by
:data:`~ecs_anim.solver.budget.MODEL_SMOOTHING`): what the three systems took per character
updated, and the rest of the tick. The updates a tick are held within
:data:`~ecs_anim.solver.budget.HOLD_SHARE` of the budget over
:data:`~ecs_anim.solver.budget.MARGIN_FLOOR`, lowered at once and raised only when the
restore share allows more (:data:`~ecs_anim.solver.budget.RESTORE_SHARE` /
:data:`~ecs_anim.solver.budget.TARGET_SHARE` of it: no alternation). The order is strict: the
update rate rests characters only once the solve keeps none (ConstraintSolve says so each tick,
:meth:`UpdateRate.note_solve`), and the solve brings constraints back only once every character
is updated every tick again (:attr:`UpdateRate.calm`; solving any character costs work over
every row, which a model measured on ticks that solved none does not see: at 19,000 one solved
took the tick from 24 to 46 ms); a constraint a trigger switches on for a resting character
waits for its next update (then no character rests from the next tick). Characters the solve
keeps (solved, held, or going back to their motion) and characters without a MotionPlayer are
updated every tick; so is everyone while the kernels compile aside or on a ground of the
user's own (the numpy paths work on all rows).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ecs_anim.components import MotionPlayer
from ecs_anim.core.errors import UsageError
from ecs_anim.core.ground import built_in
from ecs_anim.runtime.kernels import threads
from ecs_anim.solver.budget import (
    KEEP_PREFERENCE,
    MARGIN_FLOOR,
    MODEL_SMOOTHING,
    due,
    held_and_restore_ms,
    solve_intervals,
)

if TYPE_CHECKING:
    from ecs_anim.runtime.simulation import Simulation

I64 = NDArray[np.int64]

#: Every how many ticks a character is played, grounded and posed: every tick, every 2nd, 4th,
#: 8th (3.75 updates a second at 30 Hz, for the furthest characters of the largest crowds).
UPDATE_INTERVALS = (1, 2, 4, 8)
#: Ticks after the last one that rested a character before the frame budget may bring
#: constraints back (its model, calibrated on ticks that rested some, measures the whole
#: updates again: 2 / MODEL_SMOOTHING).
CALM_TICKS = 10
#: Ticks the model is not measured on after a change of the rows (the first ticks load kernels
#: and fill scratch arrays: 1.5-2 x a later tick).
WARM_TICKS = 2


def _read_only(rows: I64) -> I64:
    rows.setflags(write=False)  # (the kernels' one compiled specialisation is of read-only rows)
    return rows


def intervals_by_rank(key: NDArray[np.float64], tiers: I64) -> I64:
    """(n,) each row's interval: ``tiers`` (n,, ascending) are the intervals in rank order, the
    rank of each row that of its ``key`` (n,; the lowest first; ties may put a few more rows in
    the faster tier). O(n): a partition at the tiers' edges, no sort."""
    ends = np.flatnonzero(np.diff(tiers)) + 1  # (t - 1,) the first rank of each tier after the first
    if ends.size == 0:
        return np.full(key.size, tiers[0] if tiers.size else 1, np.int64)
    thresholds = np.partition(key, ends - 1)[ends - 1]
    values = tiers[np.concatenate(([0], ends))]
    out: I64 = values[np.searchsorted(thresholds, key, side="left")]
    return out


class UpdateRate:
    """Every how many ticks each character is played, grounded and posed (one per simulation:
    ``sim.update_rate``). Systems ask :meth:`due_rows` (or :meth:`due_groups`) for the rows to
    process this tick; ConstraintSolve tells :meth:`note_solve` what its solve keeps."""

    def __init__(self) -> None:
        #: (n,) every how many ticks each store row is updated (1: every tick).
        self.interval: I64 = np.ones(0, np.int64)
        #: Whether some character is updated less often than every tick now.
        self.resting = False
        self._given: tuple[float, float] | None = None
        self._tick: int | None = None
        self._version = -1
        self._due_mask: NDArray[np.bool_] = np.ones(0, bool)
        self._due_of: dict[int, tuple[I64, I64]] = {}
        self._playing: I64 = np.zeros(0, np.int64)
        self._grounds_built_in = True  # (every ground the compiled kernels know: may rest)
        # The model: ms per character updated by the systems that follow the rate, and the rest
        # of the tick (smoothed; None: not measured yet); the updates of the last tick decided,
        # and the updates a tick allowed (None: every character every tick).
        self._per_update_ms: float | None = None
        self._rest_ms: float | None = None
        self._last_rest_ms = 0.0
        self._updates = 0
        self._measured_ticks = 0
        self._allowance: float | None = None
        # The tick each row was last updated at (while not ``_all_current``: every row updated
        # on the last tick decided), and this tick's ticks since (None: 1 for every row).
        self._last_update: I64 = np.zeros(0, np.int64)
        self._all_current = True
        self._elapsed: I64 | None = None
        # What the solve keeps (:meth:`note_solve`): whether any character, and the rows it
        # keeps every tick.
        self._solve_keeps = False
        self._every_tick: I64 = np.zeros(0, np.int64)
        self._calm_ticks = CALM_TICKS  # (ticks since one rested any character)

    @property
    def given(self) -> tuple[float, float] | None:
        """(ms per character updated, ms the rest of the tick) taken as exact instead of
        measured (None: measured), as ``SolverSettings.cost_model`` is the solve's: the budget
        is then held in full, without a margin (tests, the docs' example). With a given solver
        model and none here, every character is updated every tick."""
        return self._given

    @given.setter
    def given(self, model: tuple[float, float] | None) -> None:
        if model is not None:
            per_update_ms, rest_ms = (float(v) for v in model)
            if not (np.isfinite(per_update_ms) and per_update_ms > 0.0
                    and np.isfinite(rest_ms) and rest_ms >= 0.0):
                raise UsageError(f"update_rate.given must be (ms an update > 0, ms the rest of "
                                 f"the tick >= 0), got {model!r}")
            model = (per_update_ms, rest_ms)
        self._given = model

    @property
    def calm(self) -> bool:
        """Whether no character rested in the last :data:`CALM_TICKS` ticks: the frame budget
        brings constraints back only then (its model measured again on ticks updating every
        character)."""
        return self._calm_ticks >= CALM_TICKS

    def note_solve(self, keeps_any: bool, every_tick_rows: I64) -> None:
        """ConstraintSolve's word each tick: whether its frame budget keeps any character's
        constraints (solved or held between two solves), and ``every_tick_rows`` (r,) the store
        rows that must be updated every tick from the next (solved, held, going back)."""
        self._solve_keeps = keeps_any
        self._every_tick = every_tick_rows

    @property
    def updated(self) -> NDArray[np.bool_]:
        """(n,) whether each store row was (or is, during a tick) updated on the last tick
        decided: every one while none rests (a viewer or exporter may tell the others apart)."""
        return self._due_mask if self.resting else np.ones(self.interval.size, bool)

    def due_rows(self, sim: Simulation, rows: I64) -> I64:
        """(d,) those of ``rows`` (a system's sorted store rows, read-only) to update this tick,
        read-only; ``rows`` itself while every character is updated every tick."""
        self._decide(sim)
        if not self.resting:
            return rows
        known = self._due_of.get(id(rows))
        if known is None or known[0] is not rows:
            known = self._due_of[id(rows)] = rows, _read_only(rows[self._due_mask[rows]])
        return known[1]

    def due_groups(self, sim: Simulation, rows: I64) -> list[tuple[int, I64]]:
        """``[(ticks, those of rows due this tick last updated that many ticks ago), ...]``: for
        a system whose step depends on the time since the row's last update (GroundAdapt's
        smoothing: ``ticks × dt``); ``[(1, rows)]`` while every character was updated on the
        last tick too."""
        due_now = self.due_rows(sim, rows)
        if self._elapsed is None:
            return [(1, due_now)]
        elapsed = self._elapsed[due_now]
        return [(int(k), _read_only(due_now[elapsed == k])) for k in np.unique(elapsed)]

    def elapsed_ticks(self, sim: Simulation) -> I64 | None:
        """(n,) the ticks since each row was last updated, counting this one (1: last tick);
        None while every row was updated on the last tick too."""
        self._decide(sim)
        return self._elapsed

    def counts(self) -> dict[int, int]:
        """How many characters are updated at each interval above 1 (ticks) now."""
        if not self.resting:
            return {}
        count = np.bincount(self.interval, minlength=UPDATE_INTERVALS[-1] + 1)
        return {k: int(count[k]) for k in UPDATE_INTERVALS[1:] if count[k]}

    def _decide(self, sim: Simulation) -> None:
        """This tick's intervals, once a tick (the first system to ask)."""
        if self._tick == sim.tick:
            return
        self._tick = sim.tick
        self._due_of.clear()
        st = sim.store
        if self._version != sim.structure_version or self.interval.size != st.n:
            # Every row is updated on the tick after a structural change: a new character has
            # no posture yet, and the rows moved.
            self._version = sim.structure_version
            self._playing = sim.rows_with(MotionPlayer)
            # (the grounds change only with the structure: a spawn or ``set_ground``)
            self._grounds_built_in = all(built_in(ground) for ground in sim.grounds)
            self._measured_ticks = 0
            self._every_tick = np.zeros(0, np.int64)
            self._update_every_row(sim, n_changed=True)
            return
        if sim.solver_settings.budget_ms is None or not sim.compiled:
            # (no budget: nothing to measure or decide; the numpy references work on every row,
            # and their time is not the kernels')
            self._measured_ticks, self._allowance = 0, None
            self._update_every_row(sim)
            return
        self._measure(sim)
        allowance = self._allowed(sim)
        self._allowance = allowance
        interval = None if allowance is None else self._tiers(sim, allowance)
        if interval is None or not (interval > 1).any():
            self._update_every_row(sim)
            return
        self._calm_ticks = 0
        self.interval = interval
        self._due_mask = due(np.arange(st.n), self.interval, sim.tick)
        self._updates = int(self._due_mask.sum())
        if self._all_current:  # (every row was updated last tick)
            self._last_update = np.full(st.n, sim.tick - 1, np.int64)
        self._elapsed = sim.tick - self._last_update
        self._last_update[self._due_mask] = sim.tick
        self._all_current = False
        self.resting = True

    def _update_every_row(self, sim: Simulation, n_changed: bool = False) -> None:
        """This tick updates every row (the rows changed, no budget, or every update fits)."""
        n = sim.store.n
        if n_changed:
            self.interval = np.ones(n, np.int64)
            self._allowance, self._elapsed = None, None
        elif not self._all_current:  # (the rows that rested catch up now)
            self.interval[:] = 1
            self._elapsed = sim.tick - self._last_update
        else:
            self._elapsed = None
        self._all_current = True  # (``_last_update`` is this tick for every row: not kept)
        self._updates = n
        self.resting = False
        self._calm_ticks += 1

    def _measure(self, sim: Simulation) -> None:
        """Move the model towards the last tick: the following systems' CPU time per update,
        the rest of the systems' (each system's last run: those before this one's first ask ran
        this tick, the others the last)."""
        scale = 1e3 / max(threads(), 1)
        following = sum(s.last_cpu_seconds for s in sim.systems if s.follows_update_rate)
        every = sum(s.last_cpu_seconds for s in sim.systems)
        self._measured_ticks += 1
        if self._solve_keeps:  # (the rest of such a tick is the solve's: measured anew after it)
            self._per_update_ms = self._rest_ms = None
            return
        if self._measured_ticks <= WARM_TICKS or self._updates <= 0:
            return

        def smoothed(old: float | None, new: float) -> float:
            return new if old is None else old + MODEL_SMOOTHING * (new - old)
        # The cost of an update is measured while every character is updated (the systems'
        # own fixed work is then a small share of it; measured on fewer, it would grow as they
        # do, and the rests with it); the rest of the tick takes what the updates do not.
        if not self.resting or self._per_update_ms is None:
            self._per_update_ms = smoothed(self._per_update_ms,
                                           following * scale / self._updates)
        self._last_rest_ms = every * scale - self._per_update_ms * self._updates
        self._rest_ms = smoothed(self._rest_ms, self._last_rest_ms)

    def _allowed(self, sim: Simulation) -> float | None:
        """The updates this tick may make (None: every character every tick): lowered at once to
        what the held share allows, raised only as far as the restore share allows."""
        settings = sim.solver_settings
        budget_ms = settings.budget_ms
        per_update_ms, rest_ms = self._per_update_ms, self._rest_ms
        if self.given is not None:
            per_update_ms, rest_ms = self.given
        elif settings.cost_model is not None:
            return None  # (a given solver model: the figures do not depend on the machine)
        if budget_ms is None or self._solve_keeps or not sim.compiled \
                or per_update_ms is None or rest_ms is None \
                or not self._grounds_built_in:
            return None
        hold_ms, restore_ms = held_and_restore_ms(budget_ms, exact=self.given is not None)
        margin = 1.0 if self.given is not None else MARGIN_FLOOR
        if self.given is None:
            # (a slower last tick counts at once: a machine slowed by other processes stays so
            # for a few ticks; a faster one only through the smoothing)
            rest_ms = max(rest_ms, self._last_rest_ms)

        def fitting(ms: float) -> float:
            return max((ms / margin - rest_ms) / max(per_update_ms, 1e-12), 0.0)

        n = sim.store.n
        most = fitting(hold_ms)
        now = float(n) if self._allowance is None else self._allowance
        allowance = min(most, max(now, fitting(restore_ms)))
        return None if allowance >= n else allowance

    def _tiers(self, sim: Simulation, allowance: float) -> I64:
        """(n,) each row's interval for ``allowance`` updates a tick: the rows the solve keeps
        and those without a MotionPlayer every tick, the others ranked by their distance from
        the focus (a row updated every tick counting :data:`KEEP_PREFERENCE` of its own), or by
        row without a focus."""
        st, focus = sim.store, sim.solver_settings.focus_in_world
        n = st.n
        if focus is not None and st.positions.shape[0] == n:
            key = np.linalg.norm(st.positions[:, 0] - np.asarray(focus), axis=1)
            key = np.where(self.interval == 1, KEEP_PREFERENCE * key, key)
        else:
            key = np.arange(n, dtype=np.float64)
        restable = np.zeros(n, bool)
        restable[self._playing] = True
        restable[self._every_tick] = False
        key = np.where(restable, key, -np.inf)
        fixed = n - int(restable.sum())
        tiers = np.ones(n, np.int64)
        tiers[fixed:] = solve_intervals(n - fixed, max(allowance - fixed, 0.0), UPDATE_INTERVALS)
        tiers[tiers == 0] = UPDATE_INTERVALS[-1]  # (no character stops: the slowest at least)
        return intervals_by_rank(key, tiers)


__all__ = ["UPDATE_INTERVALS", "UpdateRate", "intervals_by_rank"]
