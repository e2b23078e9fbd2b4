"""ConstraintSolve: every active constraint of every character, by priority (paper §9).

Gathers the store's arrays, calls the solver's tick (:func:`ecs_anim.solver.shell.constrain`:
targets, the goals, the solve of the characters with an active constraint, each constraint's
error on the result, all compiled: :mod:`ecs_anim.runtime.kernels.goals`,
:func:`ecs_anim.runtime.kernels.solve.solve`) and writes the results back. The
activation weights run on simulation time, or on the clip time of constraints stored with a
motion; a point on another character is read from its posture of the previous tick (so every
character sees the same world whatever their order), a point on the same character from this
tick's pose. A constraint whose target is not finite is switched off with one warning.
No pops (``SolverSettings.max_joint_speed_m_s``, on by default, :mod:`ecs_anim.solver.joint_speed`):
no joint moves more than that many m/s faster than the motion's own (from the pelvis), each
character's correction going the share of its way that keeps it so (the compiled
:mod:`ecs_anim.runtime.kernels.joint_speed`), and a character no longer solved goes back to its
motion's pose no faster.

Rows: characters with a Constraint component.
Reads: store.poses, lengths, posture (the previous tick's), contact_weight, clip, clip_time_s,
com_control, com_target_xy, segment_mass_kg, segment_com_fraction, last_clip_values,
last_pose_values, last_pose_joints_m, last_clip_joints_m; the constraints table.
Writes: store.poses (solved characters, and those going back), com_desired, last_clip_values,
last_pose_values, last_pose_joints_m, last_clip_joints_m, clip_positions (the motion's own
joints, None when nothing was solved), goals,
solved (the decoded result of
the solved characters, which PostureConvert takes instead of decoding them again); table.held;
table.enabled, table.weight, table.error (how far each active constraint is from being met on
the result, :func:`~ecs_anim.solver.goals.constraint_errors`; NaN while inactive).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.components import Constraint
from ecs_anim.core.normalized import DecodedPose, NormalizedPoses
from ecs_anim.motion.constraint_table import KIND_ORIENTATION
from ecs_anim.runtime.kernels import over_chunks, threads
from ecs_anim.runtime.kernels.com import centres_of_mass, segment_joints
from ecs_anim.runtime.kernels.decode import decode
from ecs_anim.runtime.kernels.goals import (
    constraint_errors as constraint_errors,  # tests patch these
)
from ecs_anim.runtime.kernels.goals import tick_goals as tick_goals
from ecs_anim.runtime.kernels.joint_speed import limit_motion, pack, step_shares
from ecs_anim.runtime.kernels.solve import solve as solve
from ecs_anim.runtime.system_base import System
from ecs_anim.solver.budget import FrameBudget, SolverReport, effective_caps
from ecs_anim.solver.goals import TickGoals
from ecs_anim.solver.joint_speed import MotionBefore, SpeedSteps, from_pelvis, solve_within_speed
from ecs_anim.solver.shell import (
    SolverSettings,
    TickResult,
    TickSteps,
    constrain,
    iteration_caps,
    scatter,
)

if TYPE_CHECKING:
    from ecs_anim.runtime.simulation import Simulation

_PROXIMAL, _DISTAL = segment_joints()


def _centres(positions: NDArray[np.float64], masses: NDArray[np.float64],
             com_fraction: NDArray[np.float64]) -> NDArray[np.float64]:
    """The compiled :func:`ecs_anim.core.morphology.centres_of_mass` (same arguments, (n, 3))."""
    n = positions.shape[0]
    out = np.empty((n, 3))
    every = np.arange(n, dtype=np.int64)
    over_chunks(centres_of_mass, n, every, every, positions, masses, com_fraction, _PROXIMAL,
                _DISTAL, out)
    return out


class ConstraintSolve(System):
    query = (Constraint,)
    reads = ("constraints", "clip", "clip_time_s", "poses", "lengths", "posture", "contact_weight",
             "com_control", "com_target_xy", "segment_mass_kg", "segment_com_fraction",
             "last_clip_values", "last_pose_values", "last_pose_joints_m", "last_clip_joints_m")
    writes = ("goals", "solved", "constraints.error", "constraints.weight",
              "constraints.enabled", "constraints.held", "poses", "com_desired",
              "last_clip_values", "last_pose_values", "last_pose_joints_m", "last_clip_joints_m",
              "clip_positions")

    def __init__(self, sim: Simulation) -> None:
        super().__init__(sim)
        #: This tick's :class:`~ecs_anim.solver.budget.SolverReport` (``sim.solver_report()``).
        self.report: SolverReport | None = None
        #: The frame budget's model and state between ticks.
        self.budget = FrameBudget()
        self._solve_cpu_s = 0.0
        # No pops: this tick's motion pose, packed (n, N_VALUES; None: not packed), and whether
        # the store's last_*_values hold the last tick's (else they are zeros: none).
        self._clip_now: NDArray[np.float64] | None = None
        self._values_kept = False
        # This tick's motion joints from the pelvis (n, N_JOINTS, 3; None: not made).
        self._clip_joints: NDArray[np.float64] | None = None
        # Each constraint's goal point at the last tick if it was fully active then (m, 3; NaN:
        # it was not), so a joint may follow a goal that moves faster than the bound.
        self._last_goals = np.zeros((0, 3))
        self._last_goals_tick = -2

    def _timed_solve(self, *args: Any) -> Any:
        """The compiled solve (within the speed bound when one is set), its CPU time kept for
        the frame budget's model."""
        start = time.process_time()
        bounded = self.sim.solver_settings.max_joint_speed_m_s is not None
        out = self._solve_within_speed(*args) if bounded else solve(*args)
        self._solve_cpu_s = time.process_time() - start
        return out

    def run(self, dt: float) -> None:
        sim, st, table = self.sim, self.sim.store, self.sim.constraints
        st.goals, st.solved, st.clip_positions = None, None, None
        self.report = None
        self._clip_now = self._clip_joints = None
        if table.m == 0:
            self._go_back(np.zeros(0, np.int64))
            return
        self.budget.start_tick(sum(system.cpu_seconds for system in sim.systems), threads(),
                               sim.structure_version, st.n)
        weight = table.weights(sim.time_s, st.clip, st.clip_time_s)
        if not self.all_rows():  # the characters without a Constraint component are not solved
            weight = np.where(self.in_rows()[table.owner], weight, 0.0)
        settings = sim.solver_settings
        wanted = weight
        if settings.budget_ms is not None:
            weight = self.budget.weights(weight, table.owner, table.priority,
                                         st.poses.root_position * sim.leg_length()[:, None],
                                         settings, sim.dt)
        unconstrained = decode(st.poses, st.lengths) if (weight > 0).any() else None
        if unconstrained is not None:
            st.clip_positions = unconstrained.positions.copy()
            if settings.max_joint_speed_m_s is not None:
                self._clip_now = pack(st.poses)
                self._clip_joints = from_pelvis(st.clip_positions)
                # A character with no last tick kept (its first, or none solved since) was at its
                # motion's pose: a constraint easing in is paced from there.
                fresh = ~np.any(st.last_pose_values != 0.0, axis=1)
                st.last_clip_values[fresh] = st.last_pose_values[fresh] = self._clip_now[fresh]
                st.last_pose_joints_m[fresh] = st.last_clip_joints_m[fresh] = \
                    self._clip_joints[fresh]
        model = settings.cost_model or self.budget.model
        if settings.budget_ms is not None and model is not None:
            model = self.budget.for_cut(model, table.owner[weight > 0])
        self._solve_cpu_s = 0.0
        result = constrain(table, weight, st.poses, unconstrained, st.lengths,
                           st.contact_weight, st.com_control, st.com_target_xy, st.segment_mass_kg,
                           st.segment_com_fraction, st.posture, self.budget.aimed(settings, model),
                           settings.release_speed_m_s * sim.dt,
                           TickSteps(tick_goals, self._timed_solve, constraint_errors, _centres),
                           model, self.budget.expected())
        used, caps = np.zeros(0, np.int64), np.zeros(0, np.int64)
        if result.goals is not None and result.iterations is not None:
            g, used = result.goals, result.iterations
            caps = effective_caps(g, *iteration_caps(g, settings), settings.iterations)
        self.budget.solved(result.rows, used, caps, self._solve_cpu_s)
        dropped = self.budget.dropped(wanted, table.owner) if settings.budget_ms is not None \
            else np.zeros(0, np.int64)
        if result.broken.size:
            sim.report_disabled(result.broken)
            table.enabled[result.broken] = False
        table.weight = result.weight
        table.error[:] = result.error
        table.held[:] = result.held
        self._report(result, dropped)
        if result.goals is None or result.poses is None or result.solved is None:
            self._go_back(np.zeros(0, np.int64))
            return
        every_row = result.rows.size == st.n
        st.poses = result.poses if every_row else scatter(st.poses, result.rows, result.poses)
        st.com_desired[result.rows] = result.goals.com_desired
        st.goals, st.solved = result.goals, result.solved
        self._go_back(result.rows)

    def _solve_within_speed(self, poses: NormalizedPoses, lengths: NDArray[np.float64],
                            goals: TickGoals, masses: NDArray[np.float64],
                            com_fraction: NDArray[np.float64], settings: SolverSettings,
                            decoded: DecodedPose | None = None, in_place: bool = False
                            ) -> tuple[NormalizedPoses, NDArray[np.int64], DecodedPose]:
        """The compiled solve (its signature), then no joint faster than the motion's by more
        than ``settings.max_joint_speed_m_s`` (:func:`solve_within_speed`)."""
        st, rows = self.sim.store, goals.rows
        assert self._clip_now is not None and self._clip_joints is not None  # before the solve
        every = rows.size == st.n  # (rows are sorted and distinct: all of them, in order)

        def of(values: NDArray[np.float64]) -> NDArray[np.float64]:
            return values if every else values[rows]

        before = MotionBefore(of(self._clip_now), of(st.last_clip_values), of(st.last_pose_values),
                              of(self._clip_joints), of(st.last_clip_joints_m),
                              of(st.last_pose_joints_m), self._goal_steps(goals))
        return solve_within_speed(SpeedSteps(solve, step_shares, limit_motion, decode), before,
                                  float(settings.max_joint_speed_m_s or np.inf) * self.sim.dt,
                                  poses, lengths, goals, masses, com_fraction, settings, decoded,
                                  in_place)

    def _goal_steps(self, goals: TickGoals) -> NDArray[np.float64]:
        """(r,) how far each solved character's fastest point goal fully active this tick and
        the last moved since (m; 0: none; a ramp's move is the bound's to spread; infinite for
        a character with a constraint switched on at once); this tick's such goals kept for the
        next."""
        table = self.sim.constraints
        if self._last_goals.shape[0] != table.m or self._last_goals_tick != self.sim.tick - 1:
            self._last_goals = np.full((table.m, 3), np.nan)  # none kept, or not the last tick's
        user = goals.table_index >= 0
        full = user & (goals.weight >= 1.0) & ~goals.orientation
        index = goals.table_index[full]
        moved = np.linalg.norm(goals.goal[full] - self._last_goals[index], axis=1)
        steps = np.zeros(goals.rows.size)
        np.maximum.at(steps, goals.owner[full], np.nan_to_num(moved, nan=0.0))
        # A constraint switched on at once (no ease: fully active, off at the last tick) asks
        # for the jump: its character is met at once this tick.
        at_once = np.zeros(goals.k, bool)
        at_once[user] = (goals.weight[user] >= 1.0) & (table.weight[goals.table_index[user]] <= 0.0)
        steps[goals.owner[at_once]] = np.inf
        self._last_goals[:] = np.nan
        self._last_goals[index] = goals.goal[full]
        self._last_goals_tick = self.sim.tick
        return steps

    def _go_back(self, solved_rows: NDArray[np.int64]) -> None:
        """The characters no longer solved whose last result was not their motion's pose (their
        constraints over) go back to it no faster than ``max_joint_speed_m_s`` allows (their
        planted feet's legs at once: the motion has those on their footprints); then this
        tick's motion poses, results and corrections are kept for the next tick."""
        st, speed = self.sim.store, self.sim.solver_settings.max_joint_speed_m_s
        if speed is None or (self._clip_now is None and not self._values_kept):
            return
        clip_now = pack(st.poses) if self._clip_now is None else self._clip_now
        corrected = np.any(st.last_pose_values != st.last_clip_values, axis=1)
        corrected[solved_rows] = False
        rows = np.flatnonzero(corrected)
        if rows.size:
            if st.clip_positions is None:  # nothing solved: every pose is the motion's
                st.clip_positions = decode(st.poses, st.lengths).positions
            planted = st.contact_weight[rows] > 0.0
            clip_joints = from_pelvis(st.clip_positions[rows])
            share = step_shares(clip_joints, clip_joints, st.last_pose_joints_m[rows],
                                st.last_clip_joints_m[rows], planted, speed * self.sim.dt,
                                np.zeros(rows.size))
            back, _ = limit_motion(st.poses.take(rows), clip_now[rows], st.last_clip_values[rows],
                                   st.last_pose_values[rows], planted, share)
            for name, value in back.arrays().items():
                getattr(st.poses, name)[rows] = value
        if self._clip_now is None and rows.size == 0:  # nothing solved nor going back
            st.last_clip_values[:], st.last_pose_values[:] = 0.0, 0.0
            st.last_pose_joints_m[:], st.last_clip_joints_m[:] = 0.0, 0.0
            self._values_kept = False
            return
        st.last_clip_values = clip_now
        st.last_pose_values = pack(st.poses)
        self._keep_joints(solved_rows, rows)
        self._values_kept = True

    def _keep_joints(self, solved_rows: NDArray[np.int64], back_rows: NDArray[np.int64]) -> None:
        """``store.last_clip_joints_m`` and ``last_pose_joints_m``: this tick's motion's joints
        and result's (the solved characters' ``store.solved``, those going back decoded here,
        the others' the motion's), from the pelvis."""
        st = self.sim.store
        assert st.clip_positions is not None  # decoded when anything was solved or goes back
        clip_joints = from_pelvis(st.clip_positions) if self._clip_joints is None \
            else self._clip_joints
        st.last_clip_joints_m = clip_joints
        if solved_rows.size == st.n and st.solved is not None:
            st.last_pose_joints_m = from_pelvis(st.solved.positions)
        else:
            st.last_pose_joints_m = clip_joints.copy()
            if solved_rows.size and st.solved is not None:
                st.last_pose_joints_m[solved_rows] = from_pelvis(st.solved.positions)
        if back_rows.size:
            back = decode(st.poses.take(back_rows), st.lengths[back_rows]).positions
            st.last_pose_joints_m[back_rows] = from_pelvis(back)

    def _report(self, result: TickResult, dropped: NDArray[np.int64]) -> None:
        """This tick's report (``dropped``: the store rows the budget switched off)."""
        sim, table = self.sim, self.sim.constraints
        settings = sim.solver_settings
        model = settings.cost_model or self.budget.model
        cut_by = None if result.cut is None else model
        used = 0 if result.iterations is None else int(result.iterations.sum())
        cut = result.cut
        cut_constraint = np.zeros(table.m, bool)
        cut_entities: tuple[int, ...] = ()
        if cut is not None and result.goals is not None:
            g = result.goals
            user = g.table_index >= 0
            lowered = user & ((cut.goal_iterations < settings.iterations)
                              | np.isin(g.owner, cut.cut_rows))
            cut_constraint[g.table_index[lowered]] = True
            cut_entities = tuple(int(e) for e in sim.store.entity[result.rows[cut.cut_rows]])
        self.report = SolverReport(
            tick=sim.tick, characters=int(result.rows.size), iterations=used,
            budget_ms=settings.budget_ms,
            model=cut_by,
            expected_ms=float("nan") if cut is None else cut.expected_ms,
            cut_ms=float("nan") if cut is None else cut.cut_ms,
            priority_iterations={} if cut is None else dict(cut.priority_iterations),
            cut_characters=cut_entities,
            constraint_errors=(table.priority.copy(), result.error,
                               table.kind == KIND_ORIENTATION, cut_constraint),
            dropped_characters=tuple(int(e) for e in sim.store.entity[dropped]),
            floor_ms=float("nan") if model is None or settings.budget_ms is None
            else model.fixed_ms)
