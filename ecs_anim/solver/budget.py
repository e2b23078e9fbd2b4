"""The frame budget (``SolverSettings.budget_ms``): the whole tick held within it, the solve degraded where it matters least.

The decision is made from a cost model, not from a clock, so that it is deterministic given the
model: a tick costs ``fixed_ms`` (every system but the constraint solve's characters, and
ConstraintSolve's own work over every row and for the characters going back), plus
``ms_per_character`` for each solved character (its goals, errors and final re-plant), plus
``ms_per_iteration`` for each iteration of each solved character, plus ``ms_per_held`` for each
character held between two solves. :class:`FrameBudget` (held by
ConstraintSolve) calibrates the model from the process's CPU time of every tick (per kernel
thread), smoothed over ticks (:data:`MODEL_SMOOTHING`): one slow tick does not swing the cut
(``SolverSettings.cost_model`` fixes it instead: tests do, and the figures then no longer depend
on the machine). Each solved character is expected to take the iterations it needed when last
solved uncut (the settings' ``iterations`` before that): a character the budget stopped at its
cap does not look cheap on the next tick, so the cut does not alternate between all and none.

A tick is held within :data:`HOLD_SHARE` of ``budget_ms`` by this tick's model
(:attr:`FrameBudget.model`): what the systems before ConstraintSolve took this tick, as
measured, plus the calibrated cost of the rest of the tick (the solve, the systems after it)
times a margin taken from the machine's observed spread (:attr:`FrameBudget.margin_factor`): the
largest recent ratio of a tick's rest to the model's cost of it, decaying by
:data:`MARGIN_DECAY` a tick (between :data:`MARGIN_FLOOR` and :data:`MARGIN_CEILING`), or, if
larger, how much slower than usual the systems before the solve ran this tick (a machine slowed
by other processes slows the whole tick, and for a few ticks at a time). A tick beyond the margin
moves the model's mean only up to it: the spread is the margin's, not counted twice. (The
margin is the price of holding every tick on a shared machine: the rest of the tick is given
1 / margin of what the systems before the solve leave of the budget.) When the tick would
overrun it, in this order:

1. the lowest-priority constraints, one priority at a time from the lowest, one iteration at a
   time down to one (:func:`cut_to_budget`): a cut goal no longer keeps its character's loop
   going nor turns the trunk (its limb still serves it analytically on every iteration the
   character makes); the highest priority is never cut here;
2. then whole characters, the furthest from the focus point (``SolverSettings.focus_in_world``;
   the viewer sets its camera's eye) first, down to one iteration each (:func:`cut_to_budget`);
3. and when even one iteration of every character does not fit, a level of detail: characters
   are solved every 2nd, 4th, 8th or 16th tick (:data:`SOLVE_INTERVALS`,
   :func:`solve_intervals`), ranked by their highest priority, then by distance from the focus
   (:func:`ranked_rows`): the most that fit solved every tick, twice as many after them every
   2nd tick, four times as many every 4th, eight times every 8th, the rest every 16th; the
   rows of one interval take turns (:func:`due`), so each tick solves about as many. Between
   two solves a character keeps its last solve's correction (:mod:`ecs_anim.solver.held_pose`:
   the trunk, arms and head as solved, the legs' and the root's correction on the motion's):
   its constraints stay about met (they move with the pelvis for up to 15 ticks) instead of
   switching off. Whether every character is solved every tick is decided by what such ticks
   measured, not by the model (:meth:`FrameBudget._every_candidate_or`: solving every row, in
   place and holding none, costs less a row than solving some, on which the model is mostly
   calibrated), with a probe now and then while they are not;
4. and when even every character every 16th tick does not fit, the last ranked are *dropped*:
   their constraints are switched off, and they play and stand on the ground as every
   unconstrained character. Dropped characters come back only once the tick with them fits in
   :data:`RESTORE_SHARE` / :data:`TARGET_SHARE` of the held share (hysteresis: between the two
   nothing changes;
   the same holds the level of detail: it goes down at once and up only past that share,
   :func:`solve_capacity`), by at most :data:`RESTORE_STEP_SHARE` of the budget a tick, their
   constraints fading in over :data:`RESTORE_RAMP_S`; a dropped character's last correction is
   forgotten (held again, it would be one from ticks ago);
5. and when even dropping every character leaves the tick over its budget (the model's
   ``fixed_ms``, ``SolverReport.floor_ms``), the characters furthest from the focus are played,
   grounded and posed every 2nd, 4th or 8th tick only (:mod:`ecs_anim.runtime.update_rate`,
   ``SolverReport.update_intervals``); no constraint comes back while any character rests,
   nor for ``update_rate.CALM_TICKS`` ticks after.

A character whose goals are all cut stops when the last of them does, so the expected cost of a
character is ``min(expected, its own cap, the largest cap of its goals)``. Feet are not goals
here (they are planted after the loop whatever the budget).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import UsageError

if TYPE_CHECKING:
    from ecs_anim.solver.goals import TickGoals
    from ecs_anim.solver.shell import SolverSettings

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


#: The share of the budget CollisionSeparate's rounds aim at (what the systems before it took
#: this tick, what those after it took last tick and its rounds); the ratio of
#: :data:`RESTORE_SHARE` to it is the solve's hysteresis.
TARGET_SHARE = 0.85
#: The share of the budget the solve's cut holds a tick in by the model with its margin: what
#: the systems before ConstraintSolve took this tick (measured) plus the model's cost of the
#: rest of the tick times :attr:`FrameBudget.margin_factor` (the rest of the budget: the clock's
#: reads and what the systems' timers do not see).
HOLD_SHARE = 0.95
#: The least margin on the model's cost of the rest of the tick (ConstraintSolve and the systems
#: after it): the model's own error on a quiet machine.
MARGIN_FLOOR = 1.1
#: The most margin: past it, a slow machine's tick is not held by cutting the solve.
MARGIN_CEILING = 2.0
#: A margin raised by a slow tick keeps this share of its excess over 1 each tick (half of it
#: after 14 ticks, about half a second at 30 Hz): a machine slowed by other processes stays so
#: for a few ticks at a time, and the solves come back in steps, not at the next tick.
MARGIN_DECAY = 0.95
#: The margin is measured once the model has been calibrated this many times (a young model's
#: errors are its own, not the machine's: 1 / :data:`MODEL_SMOOTHING`), and only on a tick
#: whose solves are within :data:`STEADY_SHARE` of the last tick's, both solving every
#: candidate or both not: the model, an average, errs when the solves change much (solving some
#: rows costs more a row than solving every row: the level of detail setting in), and the
#: calibration corrects that, not the margin.
MARGIN_AFTER = 5
STEADY_SHARE = 0.25
#: The systems before the solve tell a slowed machine within the tick only when they take at
#: least this (ms, smoothed): shorter, their own noise is larger than a slowdown.
STALL_MIN_MS = 1.0
#: Dropped characters come back once the tick with them fits in this share of the budget.
RESTORE_SHARE = 0.75
#: Each tick, the solves a tick come back by at most what the model prices at this share of the
#: budget (:func:`solve_capacity`): a model wrong about the characters coming back (their first
#: solves cost more than a kept one's: their corrections start from nothing) is wrong by that
#: much, not by the whole restore (from every character dropped to 1,681 solved a tick at once,
#: at 9,500 characters, the tick took 60 ms, 45 of them in ConstraintSolve).
RESTORE_STEP_SHARE = 0.1
#: How far each measured tick moves the model (the weight of an exponential moving average).
MODEL_SMOOTHING = 0.2
#: Seconds a restored character's constraints take to fade back in.
RESTORE_RAMP_S = 0.25
#: The solve's last pass over a character (feet re-planted, limbs and head re-aimed after the
#: loop) costs about one iteration, whatever the character's iterations.
FINAL_PASS_ITERATIONS = 1.0
#: A kept character's distance counts as this share of itself when ranking whom to solve less
#: often, so that two characters at nearly the same distance do not swap places every tick.
KEEP_PREFERENCE = 0.9
#: Every how many ticks the budget solves a character (level of detail): every tick, every 2nd,
#: 4th, 8th, 16th (about twice a second at 30 Hz); a character between two solves keeps its
#: last solve's correction (:class:`~ecs_anim.solver.held_pose.HeldCorrections`). (With 8 the
#: slowest, 7,000 walkers under 33 ms kept 3,660 and dropped the rest.)
SOLVE_INTERVALS = (1, 2, 4, 8, 16)
#: Whether every candidate is solved every tick is decided by the median rest of the tick
#: (ConstraintSolve and the systems after it, per candidate) of the last this many ticks of
#: the last run of ticks that solved every one: a slow tick among them, the first ones' above
#: all (they load kernels), does not cut them.
EVERY_CANDIDATE_TICKS = 8
#: While fewer than every candidate are solved, every this many ticks (a second at 30 Hz)
#: every one is solved once if the least such a tick ever cost, times MARGIN_FLOOR, fits in the
#: budget (a probe):
#: what it costs may have fallen since it was last measured (a slowed machine's ticks). Twice
#: as long after each probe that did not bring them back (on a slowed machine a probe cost
#: 40-45 ms where the ticks solving some took 20-30), back to this once they came back.
PROBE_TICKS = 30


@dataclass(frozen=True)
class SolverCostModel:
    """What a tick costs, ms: ``fixed_ms`` (everything but the constraint solve's characters:
    the other systems and ConstraintSolve's own floor, its work over every row), plus
    ``ms_per_character`` for each solved character (its goals, errors, final re-plant), plus
    ``ms_per_iteration`` for each iteration of each solved character, plus ``ms_per_held``
    for each character held between two solves (its held-pose step)."""

    ms_per_iteration: float
    fixed_ms: float = 0.0
    ms_per_character: float = 0.0
    ms_per_held: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.ms_per_iteration) and self.ms_per_iteration > 0.0):
            raise UsageError(f"ms_per_iteration must be a positive number, got {self.ms_per_iteration}")
        for name in ("fixed_ms", "ms_per_character", "ms_per_held"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise UsageError(f"{name} must be a number >= 0, got {value}")

    def tick_ms(self, iterations: float, characters: int = 0, held: int = 0) -> float:
        """The tick's cost for this many character-iterations of this many solved characters,
        with ``held`` characters held between two solves, ms."""
        return self.fixed_ms + self.ms_per_character * characters \
            + self.ms_per_iteration * float(iterations) + self.ms_per_held * held

    def with_characters(self, characters: int, held: int = 0) -> SolverCostModel:
        """The same model with ``characters`` solved characters' own cost and ``held``
        characters' held-pose step in ``fixed_ms`` (what :func:`cut_to_budget` decides by: it
        changes only iterations)."""
        return SolverCostModel(self.ms_per_iteration, self.fixed_ms
                               + self.ms_per_character * characters + self.ms_per_held * held)

    def with_margin(self, before_ms: float, usual_before_ms: float, factor: float
                    ) -> SolverCostModel:
        """This model for a tick whose systems before the solve took ``before_ms`` where they
        usually take ``usual_before_ms`` (part of ``fixed_ms``): the rest of the tick (the
        solve's costs and the fixed part's remainder, the systems after the solve) times
        ``factor``."""
        after_ms = max(self.fixed_ms - usual_before_ms, 0.0)
        return SolverCostModel(self.ms_per_iteration * factor, before_ms + after_ms * factor,
                               self.ms_per_character * factor, self.ms_per_held * factor)

    @staticmethod
    def calibrated(tick_ms: float, solve_ms: float, iterations: int, characters: int = 0,
                   held: int = 0, hold_ms: float = 0.0) -> SolverCostModel | None:
        """The model of a measured tick: ``tick_ms`` in all, ``solve_ms`` of it in the solve
        of ``characters`` characters, which made ``iterations`` character-iterations (None if
        it made none), ``hold_ms`` in the held-pose step of ``held`` characters. The solve's
        last pass (the re-plant after the loop) counts as :data:`FINAL_PASS_ITERATIONS` more
        iterations of each character, its own cost; all the rest is ``fixed_ms`` (ConstraintSolve
        keeps its work over every row and for the characters going back out of ``solve_ms``:
        its floor)."""
        if iterations <= 0 or not solve_ms > 0.0:
            return None
        per_iteration = solve_ms / (iterations + FINAL_PASS_ITERATIONS * characters)
        return SolverCostModel(per_iteration, max(tick_ms - solve_ms - hold_ms, 0.0),
                               FINAL_PASS_ITERATIONS * per_iteration if characters else 0.0,
                               hold_ms / held if held else 0.0)

    def smoothed(self, measured: SolverCostModel, weight: float = MODEL_SMOOTHING
                 ) -> SolverCostModel:
        """This model moved ``weight`` of the way towards ``measured`` (each cost alike; the
        held characters' only when ``measured`` held some: a tick that held none did not
        measure it)."""
        def blend(old: float, new: float) -> float:
            return old + weight * (new - old)
        return SolverCostModel(blend(self.ms_per_iteration, measured.ms_per_iteration),
                               blend(self.fixed_ms, measured.fixed_ms),
                               blend(self.ms_per_character, measured.ms_per_character),
                               blend(self.ms_per_held, measured.ms_per_held)
                               if measured.ms_per_held > 0.0 else self.ms_per_held)


@dataclass(frozen=True)
class BudgetCut:
    """What :func:`cut_to_budget` decided for the r solved characters and their k goals.

    goal_iterations (k,) and row_iterations (r,): the caps (``TickGoals`` fields of the same
    names); expected_ms / cut_ms: the tick's cost by the model before / after the cut;
    priority_iterations: each cut priority and the iterations its goals kept; cut_rows (c,)
    local rows whose own cap was lowered, furthest from the focus first."""

    goal_iterations: I64
    row_iterations: I64
    expected_ms: float
    cut_ms: float
    priority_iterations: dict[float, int]
    cut_rows: I64


def _expected_cost(goals: TickGoals, expected: I64, goal_caps: I64, row_caps: I64) -> I64:
    """(r,) the iterations each character is expected to take under these caps."""
    user = goals.table_index >= 0
    largest_goal_cap = np.zeros(goals.rows.size, np.int64)
    owner = goals.owner[user]
    if owner.size:  # (goals sorted by character: each one's largest over its run)
        starts = np.flatnonzero(np.concatenate(([True], owner[1:] != owner[:-1])))
        largest_goal_cap[owner[starts]] = np.maximum.reduceat(goal_caps[user], starts)
    cost: I64 = np.minimum(np.minimum(expected, row_caps), largest_goal_cap)
    return cost


def cut_to_budget(goals: TickGoals, expected: I64, distance_m: F64, budget_ms: float,
                  model: SolverCostModel, iterations: int) -> BudgetCut:
    """The iteration caps that bring this tick within ``budget_ms`` by ``model`` (see the module's
    docstring for the order), for ``goals`` of r characters expected to take ``expected`` (r,)
    iterations each, at ``distance_m`` (r,) from the focus point, with ``iterations`` the
    settings' budget per character. Deterministic: the same inputs give the same cut."""
    r = goals.rows.size
    goal_caps = np.full(goals.k, iterations, np.int64)
    row_caps = np.full(r, iterations, np.int64)
    expected = np.minimum(np.asarray(expected, np.int64), iterations)

    def tick_ms() -> float:
        return model.tick_ms(int(_expected_cost(goals, expected, goal_caps, row_caps).sum()))

    before = tick_ms()
    cut_priorities: dict[float, int] = {}
    cut_rows = np.zeros(0, np.int64)
    if before > budget_ms:
        user = goals.table_index >= 0
        levels = np.unique(goals.priority[user])
        within = False
        for level in levels[:-1]:  # lowest first; the top priority is not cut here
            at_level = user & (goals.priority == level)
            for cap in range(iterations - 1, 0, -1):
                goal_caps[at_level] = cap
                cut_priorities[float(level)] = cap
                if tick_ms() <= budget_ms:
                    within = True
                    break
            if within:
                break
        if not within:
            # Whole characters, furthest from the focus first, down to one iteration each.
            cost = _expected_cost(goals, expected, goal_caps, row_caps)
            order = np.lexsort((np.arange(r), -distance_m))
            saving = np.cumsum(cost[order] - 1) * model.ms_per_iteration
            over = tick_ms() - budget_ms
            count = min(int(np.searchsorted(saving, over - 1e-12, side="left")) + 1, r)
            cut_rows = order[:count]
            cut_rows = cut_rows[cost[cut_rows] > 1]
            row_caps[cut_rows] = 1
    return BudgetCut(goal_caps, row_caps, before, tick_ms(), cut_priorities, cut_rows)


def uncut_need(previous: I64, used: I64, caps: I64) -> I64:
    """(r,) the iterations each solved character is expected to need when next solved: what it
    ``used`` (r,) where it stopped before its ``caps`` (r,: the budget's cut,
    :func:`effective_caps`), else the larger of that and its ``previous`` need (r,; 0: not
    known): the budget stopped it, so what it needs is not known."""
    need: I64 = np.where(used < caps, used, np.maximum(previous, used))
    return need


def effective_caps(goals: TickGoals, goal_caps: I64, row_caps: I64, iterations: int) -> I64:
    """(r,) the most iterations each character could take under these caps (its own, and the
    largest of its goals')."""
    return _expected_cost(goals, np.full(goals.rows.size, iterations, np.int64), goal_caps,
                          row_caps)


def solve_capacity(model: SolverCostModel, capacity_now: float | None, target_ms: float,
                   restore_ms: float, candidates: int, step_ms: float = np.inf) -> float:
    """How many character solves a tick may make (a character solved every 4th tick counts a
    quarter) among ``candidates`` characters: as many as fit in ``target_ms`` by ``model`` at
    one iteration each (fewer iterations come first: :func:`cut_to_budget`), the characters
    kept but not solved this tick at ``model.ms_per_held`` each (all the candidates but those
    solved, or, when even every candidate at the slowest interval does not fit, those kept
    at it but not due: :func:`solve_intervals`); more than last tick's ``capacity_now`` (None:
    none yet) only as far as ``restore_ms`` (<= ``target_ms``) allows, so that the
    measurements' noise does not move it every tick, and by no more than ``step_ms`` of the
    model's cost at once."""
    per_solve = model.ms_per_character + model.ms_per_iteration
    slowest = SOLVE_INTERVALS[-1]
    # below every candidate kept at the slowest interval, each solve keeps slowest - 1 held
    per_solve_kept_slowest = per_solve + (slowest - 1) * model.ms_per_held
    every_kept = candidates / slowest
    every_kept_ms = model.fixed_ms + per_solve_kept_slowest * every_kept
    # above, each solve more is a held character fewer
    rise = per_solve - model.ms_per_held

    def fitting(ms: float) -> float:
        if ms < every_kept_ms:
            return max((ms - model.fixed_ms) / per_solve_kept_slowest, 0.0)
        return float(candidates) if rise <= 0.0 else every_kept + (ms - every_kept_ms) / rise

    def cost_ms(capacity: float) -> float:  # (fitting's inverse)
        if capacity < every_kept:
            return model.fixed_ms + capacity * per_solve_kept_slowest
        return every_kept_ms + max(rise, 0.0) * (capacity - every_kept)

    most = fitting(target_ms)
    if capacity_now is None or capacity_now > most:
        return most
    return max(capacity_now, min(fitting(restore_ms), fitting(cost_ms(capacity_now) + step_ms),
                                 most))


def _tier_sizes(nearest: float, candidates: int, intervals: tuple[int, ...]) -> list[int]:
    """How many of ``candidates`` ranked characters get each of ``intervals`` (1, 2, 4, ...):
    the ranks below ``nearest`` every tick, below 3 x ``nearest`` every 2nd tick, below 7 x
    every 4th, and so on; the last interval the rest."""
    ends = [min(int(np.ceil(nearest * (2 * every - 1) - 1e-9)), candidates)
            for every in intervals[:-1]] + [candidates]
    return [end - start for start, end in zip([0, *ends[:-1]], ends, strict=True)]


def _solves_per_tick(nearest: float, candidates: int, intervals: tuple[int, ...]) -> float:
    return sum(size / every for size, every in zip(_tier_sizes(nearest, candidates, intervals),
                                                   intervals, strict=True))


def solve_intervals(candidates: int, capacity: float,
                    intervals: tuple[int, ...] = SOLVE_INTERVALS) -> I64:
    """(c,) every how many ticks each of ``candidates`` characters, in rank order (the first
    the most important), is solved, 0: dropped: the most characters solved every tick such
    that the solves a tick fit in ``capacity`` with twice as many after them solved every 2nd
    tick, four times as many every 4th, the rest every ``intervals``' last (the solve's
    :data:`SOLVE_INTERVALS`; the update rate's own, :mod:`ecs_anim.runtime.update_rate`); when
    even all at the last do not fit, the last ranked are dropped. A small change of
    ``capacity`` moves only the characters at the tiers' edges."""
    slowest = intervals[-1]
    out = np.zeros(candidates, np.int64)
    if candidates / slowest > capacity:
        out[:int(capacity * slowest + 1e-9)] = slowest
        return out
    lo, hi = 0.0, float(candidates)  # the largest tier size that fits, to a 1e-3 character
    while hi - lo > 1e-3:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _solves_per_tick(mid, candidates, intervals) <= capacity + 1e-9 \
            else (lo, mid)
    out[:] = np.repeat(np.array(intervals, np.int64), _tier_sizes(lo, candidates, intervals))
    return out


def ranked_rows(top_priority: F64, distance_m: F64, kept_before: NDArray[np.bool_]) -> I64:
    """(c,) the indices of c candidate characters, the most important first: the highest
    active priority ``top_priority`` (c,) first, then the nearest the focus (``distance_m``
    (c,); a character solved last tick (``kept_before`` (c,)) counting
    :data:`KEEP_PREFERENCE` of its distance, so that two at nearly the same distance do not
    swap every tick), then the earliest."""
    order: I64 = np.lexsort((np.arange(top_priority.size),
                             np.where(kept_before, KEEP_PREFERENCE * distance_m, distance_m),
                             -top_priority))
    return order


def due(rows: I64, interval: I64, tick: int) -> NDArray[np.bool_]:
    """(r,) whether each of ``rows`` (r,: store rows) is solved at ``tick`` at its ``interval``
    (r,; 0: dropped, never): the rows of one interval take turns (by row), so each tick solves
    about the same number."""
    every = np.maximum(interval, 1)
    out: NDArray[np.bool_] = (interval > 0) & ((tick + rows) % every == 0)
    return out


def held_and_restore_ms(budget_ms: float, exact: bool) -> tuple[float, float]:
    """The tick's cost (ms) a cut holds the tick within (:data:`HOLD_SHARE` of ``budget_ms``
    for a measured model; all of it for a given one, ``exact``) and the cost under which what
    was cut comes back (that times :data:`RESTORE_SHARE` / :data:`TARGET_SHARE`: the
    hysteresis). The solve's cut and the update rate's (:mod:`ecs_anim.runtime.update_rate`)."""
    hold_ms = budget_ms * (1.0 if exact else HOLD_SHARE)
    return hold_ms, hold_ms * RESTORE_SHARE / TARGET_SHARE


def _held_and_restore_ms(settings: SolverSettings) -> tuple[float, float]:
    """:func:`held_and_restore_ms` of ``settings.budget_ms``, exact for a given ``cost_model``."""
    assert settings.budget_ms is not None
    return held_and_restore_ms(settings.budget_ms, settings.cost_model is not None)


class FrameBudget:
    """The frame budget's state between ticks (ConstraintSolve holds one, per simulation): the
    cost model calibrated from the measured ticks (``calibrated``) and this tick's (``model``:
    with what the systems before the solve took this tick and the margin), what each store row
    needed when last solved uncut, and each row's presence (n,): 1 solved, 0 dropped, in between
    its constraints fading back in. Reset when the store's rows change."""

    def __init__(self) -> None:
        #: The model calibrated from the measured ticks (smoothed; None: none yet).
        self.calibrated: SolverCostModel | None = None
        #: This tick's model, the cut's (:meth:`start_tick`; None: none yet).
        self.model: SolverCostModel | None = None
        #: The largest recent ratio of the rest of a tick (ConstraintSolve and the systems after
        #: it) to the calibrated model's cost of it, decaying (:data:`MARGIN_DECAY`).
        self.margin = MARGIN_FLOOR
        #: This tick's factor on the model's cost of the rest of the tick: :attr:`margin`, or how
        #: much slower than usual the systems before the solve ran this tick if more (1: no model).
        self.margin_factor = 1.0
        self.presence: F64 = np.ones(0)
        #: (n,) every how many ticks each row is solved (0: dropped or no constraint).
        self.interval: I64 = np.zeros(0, np.int64)
        #: This tick's rows kept but not solved: between two solves at their interval.
        self.held: I64 = np.zeros(0, np.int64)
        # This tick's rows with a constraint wanted (sorted), whom the budget solves, holds or
        # drops (:meth:`weights`).
        self._candidates: I64 = np.zeros(0, np.int64)
        #: Whether the level of detail holds characters this tick, starts to at the next or
        #: probes: the solved characters' corrections are kept (:meth:`weights`; when every
        #: candidate is solved every tick they are not: 1.4 us a character).
        self.holding = False
        self._capacity: float | None = None
        self._need: I64 = np.zeros(0, np.int64)
        self._version = -1
        self._mark_cpu_s: float | None = None
        self._marks = 0
        self._calibrations = 0
        # The last tick's solve: (its CPU s, iterations, characters), and its held-pose step:
        # (characters, CPU s), calibrated against the whole tick at the next mark; the
        # character-iterations the cut allowed last tick.
        self._last_solve: tuple[float, int, int] | None = None
        self._last_hold: tuple[int, float] = (0, 0.0)
        self._allowance: float | None = None
        # The systems before the solve, ms a tick (smoothed; this tick's before it moved), and
        # the calibrated model's cost of the rest of the last tick, ms (None: not known), against
        # which the margin is measured.
        self._usual_before_ms: float | None = None
        self._tick_usual_before_ms = 0.0
        self._rest_expected_ms: float | None = None
        # The last tick's solves: how many, and whether some candidates were not solved (held
        # or dropped; one fading back in is solved); whether every one is solved this tick.
        self._last_solves: tuple[int, bool] | None = None
        self._every_due = True
        # The rest of the ticks (ConstraintSolve and the systems after it) of the last run that
        # solved every candidate, ms per candidate (the last EVERY_CANDIDATE_TICKS), whether
        # the last tick measured was one, the least such a tick ever cost, and this tick's
        # systems before the solve, ms (:meth:`_every_candidate_or`); the ticks since every
        # one was last solved, and those a probe waits.
        self._every_rest_ms: list[float] = []
        self._every_run = False
        self._every_least_ms = np.inf
        #: Whether this tick solves every candidate to measure it (a probe,
        #: :meth:`_every_candidate_or`): the corrections kept before are kept, not renewed.
        self.probing = False
        self._corrections_current = False  # (kept on the last tick that held, none forgotten)
        self._probe_ticks = PROBE_TICKS
        self._probed = False
        self._ticks_since_every = 0
        self._tick_before_ms = 0.0

    def start_tick(self, cpu_s: float, threads: int, version: int, n: int,
                   before_s: float = 0.0) -> None:
        """At the start of ConstraintSolve's run: ``cpu_s`` every system's CPU time so far
        (s), over ``threads`` kernel threads; a whole tick lies between two marks, and the
        model moves towards it: the solve's own CPU time (:meth:`solved`) is the solved
        characters', the held-pose step's (:meth:`held_step`) the held ones', all the rest
        the fixed part's (ConstraintSolve's floor among it: its gathers over every row). The
        first two ticks are not measured (they load the kernels and take the solve's first
        paths: 1.5-2 x a later tick). ``version``/``n``: the store's structure and rows.
        ``before_s``: what the systems before ConstraintSolve took this tick (s): this tick's
        :attr:`model` counts it as it was, the rest of the tick at the calibrated model's cost
        times :attr:`margin_factor`."""
        if version != self._version or self._need.size != n:
            self._version = version
            self._need = np.zeros(n, np.int64)
            self.presence = np.ones(n)
            self.interval = np.zeros(n, np.int64)
            self._allowance = None
        scale = 1e3 / max(threads, 1)
        before_ms = before_s * scale
        if self._mark_cpu_s is not None and self._last_solve is not None and self._marks > 2:
            solve_s, iterations, characters = self._last_solve
            held, hold_s = self._last_hold
            tick_ms = (cpu_s - self._mark_cpu_s) * scale
            if self._calibrations >= MARGIN_AFTER:
                kept = self._measure_margin(tick_ms - before_ms)
                solve_s *= kept
                hold_s *= kept
                tick_ms = before_ms + kept * (tick_ms - before_ms)
            if self._last_solves is not None and self._last_solves[0] and not self._last_solves[1]:
                run = self._every_rest_ms[1 - EVERY_CANDIDATE_TICKS:] if self._every_run else []
                self._every_rest_ms = [*run, (tick_ms - before_ms) / self._last_solves[0]]
                self._every_least_ms = min(self._every_least_ms, self._every_rest_ms[-1])
            self._every_run = self._last_solves is not None and not self._last_solves[1]
            measured = SolverCostModel.calibrated(tick_ms, solve_s * scale, iterations, characters,
                                                  held, hold_s * scale)
            self._calibrations += 1
            if measured is not None:
                self.calibrated = measured if self.calibrated is None \
                    else self.calibrated.smoothed(measured)
            elif self.calibrated is not None:  # nothing solved: all but the holding is fixed
                self.calibrated = self.calibrated.smoothed(dataclasses.replace(
                    self.calibrated, fixed_ms=max(tick_ms - hold_s * scale, 0.0),
                    ms_per_held=hold_s * scale / held if held else 0.0))
        first = self._marks == 0  # (its systems load their kernels: not their usual time)
        self._mark_cpu_s = cpu_s
        self._marks += 1
        self._last_solve = None
        self._last_hold = (0, 0.0)
        self._tick_before_ms = before_ms
        usual_before = before_ms if self._usual_before_ms is None else self._usual_before_ms
        if not first:  # (smoothed as the model's fixed part, which holds this tick's too)
            self._usual_before_ms = usual_before + MODEL_SMOOTHING * (before_ms - usual_before)
        self._tick_usual_before_ms = self._usual_before_ms or 0.0
        self.model, self.margin_factor = self.calibrated, 1.0
        if self.calibrated is not None:
            stall = before_ms / usual_before if usual_before >= STALL_MIN_MS else 1.0
            self.margin_factor = min(max(self.margin, stall), MARGIN_CEILING)
            self.model = self.calibrated.with_margin(before_ms, self._tick_usual_before_ms,
                                                     self.margin_factor)
        self._rest_expected_ms = None

    def _measure_margin(self, rest_ms: float) -> float:
        """The last tick's rest (ConstraintSolve and the systems after it) took ``rest_ms``: the
        margin is the larger of its ratio to the model's cost of it and the margin decayed.
        Returns the share of the rest the model is calibrated on: a rest beyond the margin it
        had is the spread's (the margin's), not the mean's, so it is counted only up to it."""
        decayed = 1.0 + (self.margin - 1.0) * MARGIN_DECAY
        if not self._rest_expected_ms or rest_ms <= 0.0:
            self.margin = max(decayed, MARGIN_FLOOR)
            return 1.0
        ratio = rest_ms / self._rest_expected_ms
        kept = min(1.0, self.margin / ratio)
        self.margin = min(max(decayed, ratio, MARGIN_FLOOR), MARGIN_CEILING)
        return kept

    def aimed(self, settings: SolverSettings, model: SolverCostModel | None) -> SolverSettings:
        """The settings the cut decides by, ``model`` the solved characters' (:meth:`for_cut`):
        the budget held at :data:`HOLD_SHARE` of itself when the model is measured (this
        tick's, with its margin; a given ``cost_model`` is taken as exact), as the
        character-iterations it allows: fewer as soon as the model says so, more only once
        :data:`RESTORE_SHARE` / :data:`TARGET_SHARE` of that allows more than last tick (in
        between, last tick's), so the cut does not follow the measurements' noise from tick
        to tick."""
        if settings.budget_ms is None or model is None:
            return settings
        hold_ms, restore_ms = _held_and_restore_ms(settings)

        def allowed(ms: float) -> float:
            return max((ms - model.fixed_ms) / model.ms_per_iteration, 0.0)

        most = allowed(hold_ms)
        back = allowed(restore_ms)
        self._allowance = most if self._allowance is None else min(most, max(self._allowance, back))
        return dataclasses.replace(
            settings, budget_ms=max(model.tick_ms(self._allowance), 1e-9),
            cost_model=None if settings.cost_model is None else model)

    def for_cut(self, model: SolverCostModel, solved_owners: I64) -> SolverCostModel:
        """``model`` with the solved characters' own cost and the held ones' (:attr:`held`)
        in its fixed part (:meth:`SolverCostModel.with_characters`); ``solved_owners``: the
        rows of the constraints solved this tick (repeats allowed)."""
        solved = np.zeros(self.presence.size, bool)
        solved[solved_owners] = True
        return model.with_characters(int(solved.sum()), int(self.held.size))

    def expected(self) -> I64:
        """(n,) what each row is expected to take when solved (0: not known)."""
        return self._need

    def weights(self, weight: F64, owner: I64, priority: F64, pelvis_in_world: F64 | None,
                settings: SolverSettings, dt: float, tick: int, may_restore: bool = True) -> F64:
        """The constraints' ``weight`` (m,) with those of the characters not solved at ``tick``
        switched off (dropped, or between two solves at their interval: :attr:`held`) and the
        restored ones' fading in (``owner`` (m,) their store rows, ``priority`` (m,),
        ``pelvis_in_world`` (n, 3) m, read only with a ``settings.focus_in_world``: None
        without one): :func:`solve_capacity`, :func:`ranked_rows` and
        :func:`solve_intervals` decide by the model (the settings' own first). Without
        ``may_restore`` (characters rested lately under the update rate, the budget's last
        resort: :attr:`ecs_anim.runtime.update_rate.UpdateRate.calm`) no more are solved than
        last tick, and none probed."""
        model = settings.cost_model or self.model
        self.held = np.zeros(0, np.int64)
        self.holding = self.probing = False
        self._every_due = True
        self._candidates = np.zeros(0, np.int64)
        if settings.budget_ms is None or model is None:
            self._corrections_current = False
            return weight
        wants = weight > 0
        top = np.full(self.presence.size, -np.inf)
        np.maximum.at(top, owner[wants], priority[wants])
        candidate = self._candidates = np.flatnonzero(np.isfinite(top))
        # (usually every row is one: the rows' own arrays then, no gathers and scatters)
        at = slice(None) if candidate.size == self.presence.size else candidate
        hold_ms, restore_ms = _held_and_restore_ms(settings)
        capacity = solve_capacity(model, self._capacity, hold_ms,
                                  restore_ms if may_restore else 0.0, candidate.size,
                                  RESTORE_STEP_SHARE * settings.budget_ms)
        self._capacity = self._every_candidate_or(capacity, candidate.size, settings) \
            if may_restore else capacity
        interval = np.ones(candidate.size, np.int64)
        if self._capacity < candidate.size:
            tiers = solve_intervals(candidate.size, self._capacity)
            if (tiers == tiers[0]).all():  # (every one dropped, say: the ranks change nothing)
                interval = tiers
            else:
                distance = np.zeros(candidate.size)
                if settings.focus_in_world is not None:
                    assert pelvis_in_world is not None  # (given with a focus)
                    distance = np.linalg.norm(pelvis_in_world[at] - settings.focus_in_world,
                                              axis=1)
                interval[ranked_rows(top[at], distance, self.presence[at] > 0)] = tiers
        self.interval[:] = 0
        self.interval[at] = interval
        keep = interval > 0
        step = dt / RESTORE_RAMP_S
        self.presence[at] = np.where(keep, np.minimum(self.presence[at] + step, 1.0), 0.0)
        self.holding = self._capacity < candidate.size
        # The first tick of the level of detail solves every one kept, their corrections kept
        # to be held from the next (none were while every one was solved every tick).
        current = self._corrections_current
        now = keep if self.holding and not current else due(candidate, interval, tick)
        self._corrections_current = self.holding or (self.probing and current)
        self.held = candidate[keep & ~now]
        self._every_due = bool(now.all())
        if now.all() and self.presence.min(initial=1.0) >= 1.0:
            return weight
        if not now.any():  # (none solved this tick: every weight times 0, no gather)
            return weight * 0.0
        solved_now = np.zeros(self.presence.size)
        solved_now[candidate[now]] = 1.0
        return weight * (self.presence * solved_now)[owner]

    def _every_candidate_or(self, capacity: float, candidates: int, settings: SolverSettings
                            ) -> float:
        """``capacity`` (:func:`solve_capacity`, by the model), or every one of ``candidates``
        every tick, decided by what such ticks measured (with a measured model: a tick that
        solves every row does it in place and holds none, and costs less a row than one that
        solves some, on which the model is calibrated: by the model, they would not come
        back). The median rest of the tick of the last such ticks
        (:data:`EVERY_CANDIDATE_TICKS`) times :data:`MARGIN_FLOOR` plus this tick's systems
        before the solve: every one while that fits in the budget, again once it fits in the
        restore share (the hysteresis of :func:`solve_capacity`), or for one tick (a probe,
        :attr:`probing`) after :data:`PROBE_TICKS` if the least such a tick ever cost times
        :data:`MARGIN_FLOOR` fits in the budget (a probe follows ticks that held or dropped
        characters, whose first solves cost more: at 9,500 characters, where solving every one
        takes about the whole budget, a probe by the least cost alone took 41-63 ms); else
        fewer than every one. Not the :attr:`margin`: the ticks that solve
        some have the machine's spread too, and no fewer over the budget (measured: the
        bench's at 3,500 solving 700 a tick took 20-29 ms against 24-28 solving all 3,500), and
        leaving costs a tick of its own (every correction kept)."""
        self.probing = False
        if settings.cost_model is not None or not self._every_rest_ms or candidates == 0:
            return capacity
        assert settings.budget_ms is not None
        rest_ms = float(np.median(self._every_rest_ms)) * candidates
        solving_every = (self._capacity is None or self._capacity >= candidates) \
            and not self._probed
        self._ticks_since_every = 0 if solving_every else self._ticks_since_every + 1
        fits = self._tick_before_ms + MARGIN_FLOOR * rest_ms \
            <= (settings.budget_ms if solving_every else _held_and_restore_ms(settings)[1])
        if fits:
            self._probe_ticks = PROBE_TICKS
        elif self._probed:  # (the last tick probed, and they did not come back)
            self._probe_ticks *= 2
        self.probing = self._probed = not fits \
            and self._ticks_since_every >= self._probe_ticks \
            and self._tick_before_ms + MARGIN_FLOOR * self._every_least_ms * candidates \
            <= settings.budget_ms
        if fits or self.probing:
            return float(max(capacity, candidates))
        return min(capacity, candidates - 1.0)

    def held_step(self, characters: int, cpu_s: float) -> None:
        """ConstraintSolve's held-pose step this tick: ``characters`` held between two solves
        took ``cpu_s`` (s), for the next mark's calibration (:attr:`SolverCostModel.ms_per_held`)."""
        self._last_hold = (characters, cpu_s)

    def dropped(self) -> I64:
        """The store rows whose constraints the budget switched off this tick (of the rows
        with a constraint wanted, :meth:`weights`' candidates), sorted."""
        rows: I64 = self._candidates[self.presence[self._candidates] <= 0.0]
        return rows

    def intervals(self) -> dict[int, int]:
        """How many characters the budget solves at each interval (ticks; those dropped are
        not counted): this tick's level of detail."""
        count = np.bincount(self.interval)  # (small whole numbers: no sort)
        return {every: int(count[every]) for every in (np.flatnonzero(count[1:]) + 1).tolist()}

    def solved(self, rows: I64, used: I64, caps: I64, solve_cpu_s: float) -> None:
        """After the solve: ``rows`` (r,) solved, each having ``used`` (r,) iterations under
        ``caps`` (r,, :func:`effective_caps`); the CPU time (s) of ConstraintSolve's work for
        the characters it solved (their goals, targets, iterations and errors,
        :func:`~ecs_anim.solver.shell.constrain`, and the keeping of their poses, corrections
        and the bound's last results; not its decode and packing over every row, the report,
        the held ones' step nor the rows going back: over the solve alone, the model priced a
        restore at a tenth of its cost), for the next mark's calibration."""
        self._need[rows] = uncut_need(self._need[rows], used, caps)
        self._last_solve = (solve_cpu_s, int(used.sum()), int(rows.size))
        solves = (int(rows.size), not self._every_due)
        last, self._last_solves = self._last_solves, solves
        if self.calibrated is not None and last is not None and last[1] == solves[1] \
                and abs(solves[0] - last[0]) <= STEADY_SHARE * max(last[0], 1):
            every = min(self._every_rest_ms, default=None)
            rest_ms = every * rows.size if every is not None and not solves[1] \
                else self.calibrated.tick_ms(int(used.sum()), int(rows.size), int(self.held.size)) \
                - self._tick_usual_before_ms
            self._rest_expected_ms = rest_ms if rest_ms > 0.0 else None


@dataclass(frozen=True)
class PriorityError:
    """The active constraints of one priority after this tick's solve: how many, how many the
    budget cut (their goal, or their character), and their largest and mean error (metres; the
    orientations' largest angle apart, radians, 0 when there is none)."""

    count: int
    cut: int
    max_error_m: float
    mean_error_m: float
    max_error_rad: float


@dataclass(frozen=True)
class SolverReport:
    """What the solver did in one tick, and what the frame budget cut (``sim.solver_report()``).

    tick: the tick it describes; characters: how many were solved; iterations: the
    character-iterations they used in all; budget_ms: the settings' budget (None: none);
    model: the cost model the cut used (None: no budget, or not yet calibrated: the first
    tick); expected_ms / cut_ms: the tick's cost by that model before and after the cut (NaN
    without a model); priority_iterations: each cut priority and the iterations its goals kept;
    cut_characters: the entities whose own iterations were cut (to one; furthest from the focus
    first); dropped_characters: the entities whose constraints the budget switched off this
    tick (:class:`FrameBudget`), sorted; floor_ms: what the tick costs by the model with every
    character dropped (NaN without a model): over ``budget_ms``, nothing the budget cuts can
    hold it; intervals: how many characters are solved at each interval (ticks: 1 every tick,
    8 every 8th; the level of detail, :func:`solve_intervals`; dropped ones not counted);
    held_characters: how many of them were not solved this tick and kept their last solve's
    correction (:mod:`ecs_anim.solver.held_pose`; their constraints' errors are NaN in
    ``errors``, which measures only the characters solved this tick); update_intervals: how
    many characters are played, grounded and posed only every k-th tick (k: 2, 4, 8; the
    budget's last resort once every character is dropped and the tick still does not fit,
    :mod:`ecs_anim.runtime.update_rate`); errors: per priority of the active constraints, :class:`PriorityError` (made from
    ``constraint_errors`` (priority, error, orientation, cut) (m,) each, this tick's table
    columns: :func:`errors_by_priority`, when first asked for)."""

    tick: int
    characters: int
    iterations: int
    budget_ms: float | None
    model: SolverCostModel | None
    expected_ms: float
    cut_ms: float
    priority_iterations: dict[float, int]
    cut_characters: tuple[int, ...]
    constraint_errors: tuple[F64, F64, NDArray[np.bool_], NDArray[np.bool_]] = field(
        repr=False, compare=False)
    dropped_characters: tuple[int, ...] = ()
    floor_ms: float = float("nan")
    intervals: dict[int, int] = field(default_factory=dict)
    held_characters: int = 0
    update_intervals: dict[int, int] = field(default_factory=dict)

    @functools.cached_property
    def errors(self) -> dict[float, PriorityError]:
        """Per priority of the active constraints, :class:`PriorityError`."""
        return errors_by_priority(*self.constraint_errors)

    @property
    def cut(self) -> bool:
        """Whether the budget cut anything this tick."""
        return bool(self.priority_iterations or self.cut_characters or self.dropped_characters
                    or self.characters_slowed or self.update_intervals)

    @property
    def characters_slowed(self) -> int:
        """How many characters the budget solves less often than every tick."""
        return sum(count for every, count in self.intervals.items() if every > 1)

    @property
    def characters_cut(self) -> int:
        """How many characters the budget cut this tick: iterations cut to one, or dropped."""
        return len(self.cut_characters) + len(self.dropped_characters)


def errors_by_priority(priority: F64, error: F64, orientation: NDArray[np.bool_],
                       cut: NDArray[np.bool_]) -> dict[float, PriorityError]:
    """:class:`PriorityError` of each priority among the constraints whose ``error`` (m,) is
    finite (the active ones), ``cut`` (m,) those the budget cut."""
    active = np.isfinite(error)
    out: dict[float, PriorityError] = {}
    for level in np.unique(priority[active]):
        at = active & (priority == level)
        metres = at & ~orientation
        radians = at & orientation
        out[float(level)] = PriorityError(
            count=int(at.sum()), cut=int((at & cut).sum()),
            max_error_m=float(error[metres].max(initial=0.0)),
            mean_error_m=float(error[metres].mean()) if metres.any() else 0.0,
            max_error_rad=float(error[radians].max(initial=0.0)))
    return out


__all__ = ["BudgetCut", "FrameBudget", "PriorityError", "SolverCostModel", "SolverReport",
           "cut_to_budget", "due", "effective_caps", "errors_by_priority", "held_and_restore_ms",
           "ranked_rows",
           "solve_capacity", "solve_intervals",
           "uncut_need"]
