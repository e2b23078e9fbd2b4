"""The solver's frame budget (``SolverSettings.budget_ms``): fewer iterations where they matter least.

The decision is made from a cost model, not from a clock, so that it is deterministic given the
model: a tick costs ``fixed_ms`` (every system but the solver's iterations) plus
``ms_per_iteration`` for each iteration of each solved character. The simulation calibrates the
model every tick from the last tick's measured times (``SolverSettings.cost_model`` fixes it
instead: tests do, and the figures then no longer depend on the machine). Each solved character
is expected to take as many iterations as it took last tick (the settings' ``iterations`` when
it was not solved then).

When the expected tick would overrun the budget, :func:`cut_to_budget` cuts, in this order:

1. the lowest-priority constraints, one priority at a time from the lowest, one iteration at a
   time down to one: a cut goal no longer keeps its character's loop going nor turns the trunk
   (its limb still serves it analytically on every iteration the character makes); the highest
   priority is never cut here;
2. then whole characters, the furthest from the focus point (``SolverSettings.focus_in_world``;
   the viewer sets its camera's eye) first, down to one iteration each.

A character whose goals are all cut stops when the last of them does, so the expected cost of a
character is ``min(expected, its own cap, the largest cap of its goals)``. Feet are not goals
here (they are planted after the loop whatever the budget).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import UsageError

if TYPE_CHECKING:
    from ecs_anim.solver.goals import TickGoals

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


@dataclass(frozen=True)
class SolverCostModel:
    """What a tick costs, ms: ``fixed_ms`` (everything but the solver's iterations) plus
    ``ms_per_iteration`` for each iteration of each solved character."""

    ms_per_iteration: float
    fixed_ms: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.ms_per_iteration) and self.ms_per_iteration > 0.0):
            raise UsageError(f"ms_per_iteration must be a positive number, got {self.ms_per_iteration}")
        if not (np.isfinite(self.fixed_ms) and self.fixed_ms >= 0.0):
            raise UsageError(f"fixed_ms must be a number >= 0, got {self.fixed_ms}")

    def tick_ms(self, iterations: float) -> float:
        """The tick's cost for this many character-iterations, ms."""
        return self.fixed_ms + self.ms_per_iteration * float(iterations)

    @staticmethod
    def calibrated(tick_ms: float, solve_ms: float, iterations: int) -> SolverCostModel | None:
        """The model of a measured tick: ``tick_ms`` in all, ``solve_ms`` of it in the solver's
        iterations, which made ``iterations`` character-iterations (None if it made none)."""
        if iterations <= 0 or not solve_ms > 0.0:
            return None
        return SolverCostModel(solve_ms / iterations, max(tick_ms - solve_ms, 0.0))


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
    np.maximum.at(largest_goal_cap, goals.owner[user], goal_caps[user])
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
    first); errors: per priority of the active constraints, :class:`PriorityError` (made from
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

    @functools.cached_property
    def errors(self) -> dict[float, PriorityError]:
        """Per priority of the active constraints, :class:`PriorityError`."""
        return errors_by_priority(*self.constraint_errors)

    @property
    def cut(self) -> bool:
        """Whether the budget cut anything this tick."""
        return bool(self.priority_iterations or self.cut_characters)


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


__all__ = ["BudgetCut", "PriorityError", "SolverCostModel", "SolverReport", "cut_to_budget",
           "errors_by_priority"]
