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
last_pose_values, last_pose_positions, last_clip_positions, last_kept; the constraints table.
Writes: store.poses (solved characters, and those going back), com_desired, last_clip_values,
last_pose_values, last_pose_positions, last_clip_positions, last_kept (the rows whose last
result is kept: solved, held or going back), clip_positions (the motion's own joints, None
when nothing was solved nor goes back; NaN in the rows not decoded: with a frame budget those
neither solved nor going back, with nothing solved those not going back), goals, solved (the
decoded result of the solved characters, which PostureConvert takes instead of decoding them
again); table.held;
table.enabled, table.weight, table.error (how far each active constraint is from being met on
the result, :func:`~ecs_anim.solver.goals.constraint_errors`; NaN while inactive).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ecs_anim.components import Constraint
from ecs_anim.core.morphology import centres_of_mass as numpy_centres
from ecs_anim.core.normalized import DecodedPose, NormalizedPoses
from ecs_anim.core.normalized import decode as numpy_decode
from ecs_anim.core.skeleton import N_JOINTS
from ecs_anim.motion.constraint_table import KIND_ORIENTATION, TARGET_WORLD, ConstraintTable
from ecs_anim.runtime.kernels import over_chunks, threads
from ecs_anim.runtime.kernels.com import Motion, centres_of_mass
from ecs_anim.runtime.kernels.com import motion_of as motion_of  # tests patch these
from ecs_anim.runtime.kernels.decode import (
    decode,
    decode_rows,
    decoded_pose,
    empty_decoded,
    pose_arrays,
    spine_scratch,
)
from ecs_anim.runtime.kernels.goals import GoalLayouts
from ecs_anim.runtime.kernels.goals import (
    constraint_errors as constraint_errors,  # tests patch these
)
from ecs_anim.runtime.kernels.goals import errors_on_result as errors_on_result
from ecs_anim.runtime.kernels.goals import on_other_surfaces as on_other_surfaces
from ecs_anim.runtime.kernels.goals import target_points as target_points
from ecs_anim.runtime.kernels.goals import tick_goals as _compiled_tick_goals
from ecs_anim.runtime.kernels.goals import tick_goals as tick_goals
from ecs_anim.runtime.kernels.goals import weights as weights
from ecs_anim.runtime.kernels.joint_speed import (
    goal_steps,
    limit_again,
    limit_motion,
    pack,
    put_back,
    rows_differ,
    step_shares,
)
from ecs_anim.runtime.kernels.solve import solve as solve
from ecs_anim.runtime.system_base import System
from ecs_anim.solver import joint_speed as numpy_speed
from ecs_anim.solver.budget import FrameBudget, SolverReport, effective_caps
from ecs_anim.solver.goals import TickGoals
from ecs_anim.solver.held_pose import HeldCorrections
from ecs_anim.solver.joint_speed import N_VALUES, MotionBefore, SpeedSteps, solve_within_speed
from ecs_anim.solver.shell import (
    NUMPY_STEPS,
    SolverSettings,
    TickResult,
    TickSteps,
    constrain,
    iteration_caps,
    scatter,
)

if TYPE_CHECKING:
    from ecs_anim.runtime.simulation import Simulation


def _decode_some(poses: NormalizedPoses, lengths: NDArray[np.float64], rows: NDArray[np.int64]
                 ) -> DecodedPose:
    """The compiled decode of ``rows`` (r,) of ``poses`` (n,) only, into n rows: the other
    rows' positions NaN (the frame budget solves a few of many characters; the others'
    motion poses are decoded by PostureConvert)."""
    arrays = empty_decoded(poses.root_heading.shape[0])
    arrays.positions[:] = np.nan
    over_chunks(decode_rows, rows.size, rows, pose_arrays(poses), lengths, arrays,
                spine_scratch(rows.size))
    return decoded_pose(arrays)


def _numpy_decode_some(poses: NormalizedPoses, lengths: NDArray[np.float64],
                       rows: NDArray[np.int64]) -> DecodedPose:
    """:func:`_decode_some`'s numpy reference: ``rows`` decoded, every other row NaN."""
    part = numpy_decode(poses.take(rows), lengths[rows])
    out = DecodedPose(*(np.full((lengths.shape[0],) + field.shape[1:], np.nan)
                        for field in (part.positions, part.pelvis2world, part.thorax2world,
                                      part.head2world, part.leg2world, part.arm2world)))
    for name in ("positions", "pelvis2world", "thorax2world", "head2world", "leg2world",
                 "arm2world"):
        getattr(out, name)[rows] = getattr(part, name)
    return out


def _centres(positions: NDArray[np.float64], masses: NDArray[np.float64],
             com_fraction: NDArray[np.float64]) -> NDArray[np.float64]:
    """The compiled :func:`ecs_anim.core.morphology.centres_of_mass` (same arguments, (n, 3)),
    of the rows decoded (NaN elsewhere: :func:`_decode_some`)."""
    n = positions.shape[0]
    out = np.full((n, 3), np.nan)
    rows = np.flatnonzero(np.isfinite(positions[:, 0, 0]))
    over_chunks(centres_of_mass, rows.size, rows, rows, positions, masses, com_fraction, out)
    return out


def _numpy_weights(table: ConstraintTable, time_s: float, clip: NDArray[np.int64] | None,
                   clip_time_s: NDArray[np.float64] | None) -> NDArray[np.float64]:
    """The activation weights by the table itself (:func:`weights`' reference)."""
    return table.weights(time_s, clip, clip_time_s)


def _numpy_motion(positions: NDArray[np.float64], poses: NormalizedPoses,
                  masses: NDArray[np.float64], com_fraction: NDArray[np.float64],
                  last_values: NDArray[np.float64], pack_it: bool) -> Motion:
    """:func:`motion_of`'s numpy reference: the joints copied, their centres of mass
    (:func:`ecs_anim.core.morphology.centres_of_mass`), the pose packed and the rows with no last
    values (their first quaternion zeros)."""
    centres = numpy_centres(positions, masses, com_fraction)
    if not pack_it:
        return Motion(positions.copy(), centres, None, None)
    first = last_values[:, :4]
    fresh = ((first[:, 0] == 0.0) & (first[:, 1] == 0.0) & (first[:, 2] == 0.0)
             & (first[:, 3] == 0.0))
    return Motion(positions.copy(), centres, numpy_speed.pack(poses), fresh)


def _where_kept(kept: NDArray[np.bool_], result: NDArray[np.float64],
                motion: NDArray[np.float64]) -> NDArray[np.float64]:
    """The last tick's ``result`` (r, ...) where it was kept (``kept`` (r,)), its ``motion``'s
    elsewhere (the rows neither solved, held nor going back then: at their motion's pose)."""
    if kept.all():
        return result
    out: NDArray[np.float64] = np.where(kept.reshape((-1,) + (1,) * (result.ndim - 1)),
                                        result, motion)
    return out


def _at_motion_before(before: MotionBefore, fresh: NDArray[np.bool_]) -> MotionBefore:
    """``before`` with its rows ``fresh`` (r,), which have no last tick kept (their first solved,
    or the first since they were last), as though their last tick was at this tick's motion
    pose: a constraint easing in is paced from there (new arrays: ``before``'s may be the
    store's own)."""
    values, joints = fresh[:, None], fresh[:, None, None]
    return before._replace(
        clip_before=np.where(values, before.clip_now, before.clip_before),
        pose_before=np.where(values, before.clip_now, before.pose_before),
        clip_positions_before=np.where(joints, before.clip_positions,
                                       before.clip_positions_before),
        pose_positions_before=np.where(joints, before.clip_positions,
                                       before.pose_positions_before))


class _KnownCentres:
    """The solve's centres step (:class:`~ecs_anim.solver.shell.TickSteps`) when the centres
    of mass of the motion's joints ``positions`` were made with their copy (:func:`motion_of`):
    ``centres`` for those joints (a new array each tick: the caller may write it), ``step``
    for any other."""

    def __init__(self, positions: NDArray[np.float64], centres: NDArray[np.float64],
                 step: Callable[..., NDArray[np.float64]]) -> None:
        self.positions, self.centres, self.step = positions, centres, step

    def __call__(self, positions: NDArray[np.float64], masses: NDArray[np.float64],
                 com_fraction: NDArray[np.float64]) -> NDArray[np.float64]:
        if positions is self.positions:
            return self.centres
        out: NDArray[np.float64] = self.step(positions, masses, com_fraction)
        return out


class Steps(NamedTuple):
    """The functions one tick of the solve calls: the compiled ones, or their numpy references
    while the kernels compile aside (``Simulation.compiled``)."""

    goals: Callable[..., TickGoals | None]
    solve: Callable[..., tuple[NormalizedPoses, NDArray[np.int64], DecodedPose]]
    errors: Callable[..., NDArray[np.float64]]
    result_errors: Callable[..., NDArray[np.float64]]
    centres: Callable[..., NDArray[np.float64]]
    targets: Callable[..., NDArray[np.float64]]
    decode: Callable[..., DecodedPose]
    decode_some: Callable[..., DecodedPose]
    shares: Callable[..., NDArray[np.float64]]
    limit_motion: Callable[..., tuple[NormalizedPoses, Any]]
    pack: Callable[[NormalizedPoses], NDArray[np.float64]]
    goal_steps: Callable[..., NDArray[np.float64]]
    rows_differ: Callable[..., NDArray[np.bool_]]
    limit_again: Callable[..., tuple[NormalizedPoses, DecodedPose]]
    put_back: Callable[..., None]
    surfaces: Callable[..., NDArray[np.float64]]
    weights: Callable[..., NDArray[np.float64]]
    motion: Callable[..., Motion]


def steps(compiled: bool) -> Steps:
    """The compiled steps (this module's names, read at each call: tests patch them), or their
    numpy references."""
    if compiled:
        return Steps(tick_goals, solve, constraint_errors, errors_on_result, _centres,
                     target_points, decode, _decode_some, step_shares, limit_motion, pack,
                     goal_steps, rows_differ, limit_again, put_back, on_other_surfaces, weights,
                     motion_of)
    return Steps(NUMPY_STEPS.goals, NUMPY_STEPS.solve, NUMPY_STEPS.errors,
                 NUMPY_STEPS.result_errors, numpy_centres, NUMPY_STEPS.targets, numpy_decode,
                 _numpy_decode_some, numpy_speed.step_shares, numpy_speed.limit_motion,
                 numpy_speed.pack, numpy_speed.goal_steps, numpy_speed.rows_differ,
                 numpy_speed.limit_again, numpy_speed.put_back, NUMPY_STEPS.surfaces,
                 _numpy_weights, _numpy_motion)


class ConstraintSolve(System):
    query = (Constraint,)
    reads = ("constraints", "clip", "clip_time_s", "poses", "lengths", "posture", "contact_weight",
             "com_control", "com_target_xy", "segment_mass_kg", "segment_com_fraction",
             "last_clip_values", "last_pose_values", "last_pose_positions", "last_clip_positions",
             "last_kept")
    writes = ("goals", "solved", "constraints.error", "constraints.weight",
              "constraints.enabled", "constraints.held", "poses", "com_desired",
              "last_clip_values", "last_pose_values", "last_pose_positions", "last_clip_positions",
              "last_kept", "clip_positions")

    def __init__(self, sim: Simulation) -> None:
        super().__init__(sim)
        #: This tick's :class:`~ecs_anim.solver.budget.SolverReport` (``sim.solver_report()``).
        self.report: SolverReport | None = None
        #: The frame budget's model and state between ticks.
        self.budget = FrameBudget()
        #: The last solve's correction of each character the budget solves every few ticks.
        self.corrections = HeldCorrections()
        # No pops: this tick's motion pose, packed (n, N_VALUES; None: not packed), and which
        # rows have no last tick kept (n,; None: not packed).
        self._clip_now: NDArray[np.float64] | None = None
        self._fresh: NDArray[np.bool_] | None = None
        # The rows whose last result the store keeps (``store.last_kept``, sorted) and the
        # store's structure they index; whether the store's last_pose_* arrays are this
        # system's own buffers (else they may be a tick's results kept without a copy, which
        # nothing may write). The bound's bookkeeping so costs the rows it bounds: over every
        # row, solving one character of 19,000 cost ConstraintSolve 20 ms more.
        self._kept: tuple[NDArray[np.int64], int] = (np.zeros(0, np.int64), -1)
        self._own_last = False
        # Each constraint's goal point at the last tick if it was fully active then (m, 3; NaN:
        # it was not), so a joint may follow a goal that moves faster than the bound.
        self._last_goals = np.zeros((0, 3))
        self._last_goals_tick = -2
        # The compiled goals' layout, kept while the same constraints are active.
        self._goal_layouts = GoalLayouts()
        # The rows the frame budget dropped last tick, their entities and the store's structure
        # then (:meth:`_entities_dropped`).
        self._dropped: tuple[NDArray[np.int64], tuple[int, ...], int] = (
            np.zeros(0, np.int64), (), -1)
        # This tick's rows going back to their motion's pose (:meth:`_go_back`); its rows held
        # (:meth:`_hold`) and, packed before their correction was put on when nothing else was
        # (h, N_VALUES), their motion's values; whether the store's last_clip_values hold any
        # row (else zeros); this tick's CPU time (s) of the work that is not the solved
        # characters' (:meth:`_apart`).
        self._held_rows = np.zeros(0, np.int64)
        self._held_motion = np.zeros((0, N_VALUES))
        self._values_kept = False
        self._apart_s = 0.0
        self._back_rows = np.zeros(0, np.int64)

    def _solve(self, *args: Any) -> Any:
        """The compiled solve (within the speed bound when one is set)."""
        bounded = self.sim.solver_settings.max_joint_speed_m_s is not None
        return self._solve_within_speed(*args) if bounded else steps(self.sim.compiled).solve(*args)

    def run(self, dt: float) -> None:
        self._back_rows = self._held_rows = np.zeros(0, np.int64)
        self._constrain(dt)
        # (the update rate rests characters only once the budget keeps none: its last resort;
        # before its model is made, the budget solves every one)
        kept = self.report is not None and (self.report.characters > 0
                                            or bool(self.budget.interval.any()))
        self.sim.update_rate.note_solve(kept, self._back_rows)

    def _constrain(self, dt: float) -> None:
        sim, st, table = self.sim, self.sim.store, self.sim.constraints
        step = steps(sim.compiled)
        st.goals, st.solved, st.clip_positions = None, None, None
        self.report = None
        self._clip_now = self._fresh = None
        if table.m == 0:
            self._go_back(np.zeros(0, np.int64))
            return
        before = sim.systems[:sim.systems.index(self)]  # (this tick's runs: known to the budget)
        self.budget.start_tick(sum(system.cpu_seconds for system in sim.systems), threads(),
                               sim.structure_version, st.n,
                               sum(system.last_cpu_seconds for system in before))
        weight = step.weights(table, sim.time_s, st.clip, st.clip_time_s)
        if not self.all_rows():  # the characters without a Constraint component are not solved
            weight = np.where(self.in_rows()[table.owner], weight, 0.0)
        settings = sim.solver_settings
        solving, motion = np.zeros(0, np.int64), None
        if settings.budget_ms is not None:
            # (the pelvises only rank by the distance from a focus: without one, no leg lengths,
            # 0.3 ms a tick at 19,000)
            pelvis = None if settings.focus_in_world is None \
                else st.poses.root_position * sim.leg_length()[:, None]
            weight = self.budget.weights(weight, table.owner, table.priority, pelvis, settings,
                                         sim.dt, sim.tick, sim.update_rate.calm)
            if sim.update_rate.resting:  # (a constraint switched on: not on a stale pose)
                weight = np.where(sim.update_rate.updated[table.owner], weight, 0.0)
        # (the solved characters' work from here on, for the frame budget's model: their
        # decode, solve and keeping, not the work over every row nor for the other characters)
        start, self._apart_s = time.process_time(), 0.0
        if settings.budget_ms is not None and self.budget.holding:
            # the motion's pose of the characters solved now, for their correction to be held
            self.corrections.start_tick(st.poses, sim.structure_version)
            # (a dropped character's correction is forgotten: held again, it would be old)
            self.corrections.known &= self.budget.interval > 0
            solving = np.unique(table.owner[weight > 0])
            motion = st.poses.take(solving) if solving.size else None  # (none: nothing solved)
        elif settings.budget_ms is not None and not self.budget.probing:
            # (every one solved, none held: no correction kept, 1.4 us a character; the first
            # tick of a level of detail solves every one again, to keep theirs)
            self.corrections.known[:] = False
        unconstrained = None
        if motion is not None:
            # (and the characters their targets lie on: read from this tick's pose on the
            # first tick, or for a character new since the last)
            on_body = (weight > 0) & (table.target_kind != TARGET_WORLD)
            with self._apart():  # (mostly the NaN it writes over every row; a restore aside)
                unconstrained = step.decode_some(st.poses, st.lengths,
                                                 np.union1d(solving, table.target_row[on_body]))
        elif (weight > 0).any():
            with self._apart():
                unconstrained = step.decode(st.poses, st.lengths)
        centres = step.centres
        if unconstrained is not None:
            # The motion's joints copied (the solve writes its result over the decode's), their
            # centres of mass and (the poses still in cache: the decode's) the bound's values
            # packed, in one pass over the rows.
            with self._apart():
                motion_now = step.motion(unconstrained.positions, st.poses, st.segment_mass_kg,
                                         st.segment_com_fraction, st.last_clip_values,
                                         settings.max_joint_speed_m_s is not None)
            st.clip_positions = motion_now.positions
            centres = _KnownCentres(unconstrained.positions, motion_now.centres, step.centres)
            self._clip_now, self._fresh = motion_now.packed, motion_now.fresh
        model = settings.cost_model or self.budget.model
        if settings.budget_ms is not None and model is not None:
            model = self.budget.for_cut(model, table.owner[weight > 0])
        # the compiled goals with their layout kept from tick to tick (unless a test patched them)
        goal_step = self._goal_layouts if step.goals is _compiled_tick_goals else step.goals
        result = constrain(table, weight, st.poses, unconstrained, st.lengths,
                           st.contact_weight, st.com_control, st.com_target_xy, st.segment_mass_kg,
                           st.segment_com_fraction, st.posture, self.budget.aimed(settings, model),
                           settings.release_speed_m_s * sim.dt,
                           TickSteps(goal_step, self._solve, step.errors, centres,
                                     step.targets, step.result_errors, step.surfaces),
                           model, self.budget.expected())
        used, caps = np.zeros(0, np.int64), np.zeros(0, np.int64)
        if result.goals is not None and result.iterations is not None:
            g, used = result.goals, result.iterations
            if g.goal_iterations is None and g.row_iterations is None:
                # no cut: every goal and character has the settings' iterations, and every
                # character solved has a goal of its own (what effective_caps gives then)
                caps = np.full(used.size, int(settings.iterations), np.int64)
            else:
                caps = effective_caps(g, *iteration_caps(g, settings), settings.iterations)
        dropped = self.budget.dropped() if settings.budget_ms is not None \
            else np.zeros(0, np.int64)
        if result.broken.size:
            sim.report_disabled(result.broken)
            table.enabled[result.broken] = False
        table.weight = result.weight
        table.error[:] = result.error
        table.held[:] = result.held
        with self._apart():
            self._report(result, dropped)
        if result.goals is None or result.poses is None or result.solved is None:
            self._go_back(self._hold())
            self.budget.solved(result.rows, used, caps,
                               time.process_time() - start - self._apart_s)
            return
        every_row = result.rows.size == st.n
        if motion is not None:
            self.corrections.keep(result.rows, motion.take(np.searchsorted(solving, result.rows)),
                                  result.poses)
        if every_row:
            st.poses = result.poses
        elif motion is not None:  # (the store's poses are this tick's, written whole by playback)
            for name, value in result.poses.arrays().items():
                getattr(st.poses, name)[result.rows] = value
        else:
            st.poses = scatter(st.poses, result.rows, result.poses)
        if every_row:  # (the rows sorted and distinct: all of them, in order; no row gather)
            st.com_desired[:] = result.goals.com_desired
        else:
            st.com_desired[result.rows] = result.goals.com_desired
        st.goals, st.solved = result.goals, result.solved
        held = self._hold()
        self._go_back(np.union1d(result.rows, held) if held.size else result.rows)
        self.budget.solved(result.rows, used, caps, time.process_time() - start - self._apart_s)

    @contextmanager
    def _apart(self) -> Iterator[None]:
        """Times what it holds as work that is not the solved characters' (over every row, or
        for the characters going back), out of their cost for the frame budget's model."""
        start = time.process_time()
        try:
            yield
        finally:
            self._apart_s += time.process_time() - start

    def _hold(self) -> NDArray[np.int64]:
        """Put their last solve's correction on the characters the budget solves every few
        ticks and did not solve this tick (those solved before); returns their rows. When
        nothing else packed the motion's values this tick, theirs are packed first (the bound
        keeps their correction). Timed on its own: the frame budget's cost of a held
        character."""
        if self.sim.solver_settings.budget_ms is None:
            return np.zeros(0, np.int64)
        start = time.process_time()
        st = self.sim.store
        rows = self._held_rows = self.budget.held[self.corrections.known[self.budget.held]]
        if rows.size:
            if self._clip_now is None and self.sim.solver_settings.max_joint_speed_m_s is not None:
                self._held_motion = steps(self.sim.compiled).pack(st.poses.take(rows))
            self.corrections.put_on(st.poses, rows)
        hold_s = time.process_time() - start
        self._apart_s += hold_s
        self.budget.held_step(int(rows.size), hold_s)
        return rows

    def _solve_within_speed(self, poses: NormalizedPoses, lengths: NDArray[np.float64],
                            goals: TickGoals, masses: NDArray[np.float64],
                            com_fraction: NDArray[np.float64], settings: SolverSettings,
                            decoded: DecodedPose | None = None, in_place: bool = False
                            ) -> tuple[NormalizedPoses, NDArray[np.int64], DecodedPose]:
        """The compiled solve (its signature), then no joint faster than the motion's by more
        than ``settings.max_joint_speed_m_s`` (:func:`solve_within_speed`)."""
        st, rows = self.sim.store, goals.rows
        assert self._clip_now is not None and st.clip_positions is not None  # before the solve
        every = rows.size == st.n  # (rows are sorted and distinct: all of them, in order)

        def of(values: NDArray[Any]) -> NDArray[Any]:
            return values if every else values[rows]

        step = steps(self.sim.compiled)
        # (a row not kept was at its motion's pose; one with no last tick is paced from this one)
        kept = of(st.last_kept)
        clip_before, clip_joints_before = of(st.last_clip_values), of(st.last_clip_positions)
        before = MotionBefore(of(self._clip_now), clip_before,
                              _where_kept(kept, of(st.last_pose_values), clip_before),
                              of(st.clip_positions), clip_joints_before,
                              _where_kept(kept, of(st.last_pose_positions), clip_joints_before),
                              self._goal_steps(goals, step))
        assert self._fresh is not None  # (packed with the motion's values)
        fresh = of(self._fresh)
        if fresh.any():
            before = _at_motion_before(before, fresh)
        return solve_within_speed(SpeedSteps(step.solve, step.shares, step.limit_motion,
                                             step.limit_again, step.put_back), before,
                                  float(settings.max_joint_speed_m_s or np.inf) * self.sim.dt,
                                  poses, lengths, goals, masses, com_fraction, settings, decoded,
                                  in_place)

    def _goal_steps(self, goals: TickGoals, step: Steps) -> NDArray[np.float64]:
        """(r,) how far each solved character's fastest point goal fully active this tick and
        the last moved since (:func:`~ecs_anim.solver.joint_speed.goal_steps`, against the
        table's weights of the last tick); this tick's such goals kept for the next."""
        table = self.sim.constraints
        if self._last_goals.shape[0] != table.m or self._last_goals_tick != self.sim.tick - 1:
            self._last_goals = np.full((table.m, 3), np.nan)  # none kept, or not the last tick's
        self._last_goals_tick = self.sim.tick
        out: NDArray[np.float64] = step.goal_steps(goals, self._last_goals, table.weight)
        return out

    def _go_back(self, solved_rows: NDArray[np.int64]) -> None:
        """The characters no longer solved whose last result was not their motion's pose (their
        constraints over, or the frame budget's cut) go back to it no faster than
        ``max_joint_speed_m_s`` allows (their planted feet's legs at once: the motion has those
        on their footprints); then this tick's motion poses, results and corrections are kept
        for the next tick (:meth:`_keep`). ``solved_rows`` (sorted, distinct): the rows solved
        or held this tick."""
        st, speed = self.sim.store, self.sim.solver_settings.max_joint_speed_m_s
        if speed is None:
            self._forget()
            return
        kept_before = self._kept_rows()
        if self._clip_now is None and self._held_rows.size == 0 and kept_before.size == 0 \
                and not self._values_kept:
            return  # nothing solved, held nor kept now or at the last tick
        step = steps(self.sim.compiled)
        if solved_rows.size == st.n:  # (sorted and distinct: every row) none goes back
            gone = np.zeros(0, np.int64)
        else:
            gone = kept_before[~np.isin(kept_before, solved_rows, assume_unique=True)] \
                if solved_rows.size else kept_before
        rows = gone[step.rows_differ(st.last_pose_values[gone], st.last_clip_values[gone])]
        self._back_rows = rows
        back: NormalizedPoses | None = None
        back_motion = step.pack(st.poses.take(rows)) if self._clip_now is None \
            else self._clip_now[rows]
        if rows.size:
            with self._apart():
                clip_positions = self._motion_joints(rows, step)
                planted = st.contact_weight[rows] > 0.0
                pose_before, clip_before = self._joints_before(rows, clip_positions,
                                                               back_motion, planted, step)
                share = step.shares(clip_positions, clip_positions, pose_before, clip_before,
                                    planted, speed * self.sim.dt, np.zeros(rows.size))
                back, _ = step.limit_motion(st.poses.take(rows), back_motion,
                                            st.last_clip_values[rows], st.last_pose_values[rows],
                                            planted, share)
                for name, value in back.arrays().items():
                    getattr(st.poses, name)[rows] = value
        self._keep(kept_before, solved_rows, rows, back_motion, back)

    def _forget(self) -> None:
        """No last tick kept (the bound switched off: on again, no character goes back from a
        correction of ticks ago)."""
        st, kept = self.sim.store, self._kept_rows()
        if kept.size or self._values_kept:
            st.last_kept[kept] = False
            st.last_clip_values = np.zeros_like(st.last_clip_values)
            self._kept = (np.zeros(0, np.int64), self.sim.structure_version)
            self._values_kept = False

    def _joints_before(self, rows: NDArray[np.int64], clip_positions: NDArray[np.float64],
                       motion_values: NDArray[np.float64], planted: NDArray[np.bool_],
                       step: Steps) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The last tick's result's and motion's joints (r, N_JOINTS, 3) of ``rows`` (r,) going
        back; a row held then (its joints not decoded, NaN) as though its correction then were
        on this tick's motion (``clip_positions`` (r, N_JOINTS, 3), ``motion_values``
        (r, N_VALUES)): its way back is bounded by the correction it has (left free, a
        character whose constraint ended between two solves went back in one tick)."""
        st = self.sim.store
        pose_before, clip_before = st.last_pose_positions[rows], st.last_clip_positions[rows]
        held = np.flatnonzero(~np.isfinite(pose_before[:, 0, 0]))
        if held.size:
            corrected, _ = step.limit_motion(st.poses.take(rows[held]), motion_values[held],
                                             st.last_clip_values[rows[held]],
                                             st.last_pose_values[rows[held]], planted[held],
                                             np.zeros(held.size))
            pose_before[held] = step.decode(corrected, st.lengths[rows[held]]).positions
            clip_before[held] = clip_positions[held]
        return pose_before, clip_before

    def _kept_rows(self) -> NDArray[np.int64]:
        """The rows whose last result the store keeps (sorted): those kept at the last tick, or,
        once the store's rows changed, ``store.last_kept``'s (read once)."""
        rows, version = self._kept
        if version != self.sim.structure_version:
            rows = np.flatnonzero(self.sim.store.last_kept)
            self._kept, self._own_last = (rows, self.sim.structure_version), False
        return rows

    def _motion_joints(self, rows: NDArray[np.int64], step: Steps) -> NDArray[np.float64]:
        """(r, N_JOINTS, 3) world m: the motion's joints of ``rows`` (r,) this tick, as decoded
        before the solve, or decoded here (a row the frame budget did not solve, or nothing was
        solved) and written into ``store.clip_positions`` (NaN in the rows not decoded), where
        the metrics read them."""
        st = self.sim.store
        if st.clip_positions is None:
            st.clip_positions = np.full((st.n, N_JOINTS, 3), np.nan)
        joints = st.clip_positions[rows]
        missing = ~np.isfinite(joints[:, 0, 0])
        if missing.any():
            some = rows[missing]
            joints[missing] = step.decode(st.poses.take(some), st.lengths[some]).positions
            st.clip_positions[some] = joints[missing]
        return joints

    def _keep(self, kept_before: NDArray[np.int64], solved_rows: NDArray[np.int64],
              back_rows: NDArray[np.int64], back_motion: NDArray[np.float64],
              back: NormalizedPoses | None) -> None:
        """The store's last tick for the next one. The motion's (``last_clip_values``,
        ``last_clip_positions``): every row's when anything was solved (this tick's arrays
        themselves: no copy), else those of the rows held and going back, ``back_rows`` (b,;
        their values ``back_motion`` (b, N_VALUES)), the others' zeros (none: a row next solved
        is paced from its motion's pose then). The result's (``last_pose_values``,
        ``last_pose_positions``, ``last_kept``) of the rows solved or held (``solved_rows``,
        sorted, when anything was solved; else the held ones) and going back: the solved
        characters' ``store.solved``, the held ones' pose and NaN joints (not decoded: their
        bound is taken from their correction, :meth:`_joints_before`), the poses ``back``
        (None: none) decoded here; every other row was at its motion's pose."""
        st, step = self.sim.store, steps(self.sim.compiled)
        solved, held = self._clip_now is not None, self._held_rows
        base = solved_rows if solved else held
        kept = np.union1d(base, back_rows) if back_rows.size else base
        if kept.size == st.n:
            st.last_kept[:] = True
        else:
            st.last_kept[kept_before] = False
            st.last_kept[kept] = True
        self._kept = (kept, self.sim.structure_version)
        if self._clip_now is not None:
            assert st.clip_positions is not None  # (decoded with the motion's values)
            st.last_clip_values, st.last_clip_positions = self._clip_now, st.clip_positions
        else:
            st.last_clip_values = np.zeros_like(st.last_clip_values)
            st.last_clip_values[back_rows] = back_motion
            st.last_clip_values[held] = self._held_motion
            # (decoded for the rows going back only; the held ones' NaN: not decoded)
            if st.clip_positions is None:
                st.last_clip_positions = np.zeros_like(st.last_clip_positions)
                st.last_clip_positions[held] = np.nan
            else:
                st.last_clip_positions = st.clip_positions
        self._values_kept = solved or kept.size > 0
        if kept.size == 0:
            return
        goals = st.goals
        solved_now = goals.rows if st.solved is not None and isinstance(goals, TickGoals) \
            else np.zeros(0, np.int64)
        if kept.size == st.n:  # (sorted and distinct: every row) this tick's arrays
            st.last_pose_values = step.pack(st.poses)
            if solved_now.size == st.n and st.solved is not None and back is None:
                st.last_pose_positions = st.solved.positions
                self._own_last = False
                return
            st.last_pose_positions = st.last_clip_positions.copy()
            self._own_last = True
        else:
            if not self._own_last:  # (a tick's arrays: the kept rows go into arrays of its own)
                st.last_pose_values = np.zeros_like(st.last_pose_values)
                st.last_pose_positions = np.zeros_like(st.last_pose_positions)
                self._own_last = True
            st.last_pose_values[kept] = step.pack(st.poses.take(kept))
            st.last_pose_positions[kept] = st.last_clip_positions[kept]
        if solved_now.size and st.solved is not None:
            st.last_pose_positions[solved_now] = st.solved.positions
        if back is not None:
            st.last_pose_positions[back_rows] = step.decode(back, st.lengths[back_rows]).positions
        st.last_pose_positions[held] = np.nan

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
            cut_entities = tuple(sim.store.entity[result.rows[cut.cut_rows]].tolist())
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
            dropped_characters=self._entities_dropped(dropped),
            floor_ms=float("nan") if model is None or settings.budget_ms is None
            else model.fixed_ms,
            intervals={} if settings.budget_ms is None else self.budget.intervals(),
            held_characters=0 if settings.budget_ms is None
            else int(self.corrections.known[self.budget.held].sum()),
            update_intervals=sim.update_rate.counts())

    def _entities_dropped(self, rows: NDArray[np.int64]) -> tuple[int, ...]:
        """The entities of the store ``rows`` (r,) the frame budget dropped this tick, the last
        tick's tuple again while they are the same rows of the same store (listing 19,000 of
        them took 0.3 ms a tick)."""
        last_rows, entities, version = self._dropped
        if version != self.sim.structure_version or not np.array_equal(rows, last_rows):
            entities = tuple(self.sim.store.entity[rows].tolist())
            self._dropped = (rows, entities, self.sim.structure_version)
        return entities
