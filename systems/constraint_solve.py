"""ConstraintSolve: every active constraint of every character, by priority (paper §9).

Once per tick: the activation weights (simulation time, or the clip time of constraints stored
with a motion), the targets (world points; a point on another character from its posture of the
previous tick, so every character sees the same world whatever their order; a point on the same
character from this tick's pose), then the solver shell (:mod:`ecs_anim.solver_shell`) iterates
legs, head, arms, trunk and the root (``adaptRoot``, the centre-of-mass control the paper places
inside the loop after the trunk) for the characters that have an active constraint, all at once.
A constraint whose target is not finite is switched off with one warning; the others go on.

Rows: characters with a Constraint component.
Reads: store.poses, lengths, posture (the previous tick's), contact_weight, clip, clip_time_s,
com_control, com_target_xy, segment_mass_kg, segment_com_fraction; the constraints table.
Writes: store.poses (solved characters), com_desired, goals, solved_positions; table.held;
table.enabled, table.weight, table.error (how far each active constraint is from being met on
the result, :func:`~ecs_anim.solver_shell.constraint_errors`; NaN while inactive).
"""

from __future__ import annotations

from dataclasses import fields

import numpy as np
from ecs_anim.components import Constraint

from ecs_anim.constraint_table import TARGET_WORLD
from ecs_anim.morphology import centres_of_mass
from ecs_anim.normalized import DecodedPose, decode
from ecs_anim.solver_shell import constraint_errors, scatter, solve, target_points, tick_goals
from ecs_anim.system_base import System


class ConstraintSolve(System):
    query = (Constraint,)
    reads = ("constraints", "clip", "clip_time_s", "poses", "lengths", "posture", "contact_weight",
             "com_control", "com_target_xy", "segment_mass_kg", "segment_com_fraction")
    writes = ("goals", "solved_positions", "constraints.error", "constraints.weight",
              "constraints.enabled", "constraints.held", "poses", "com_desired")

    def run(self, dt: float) -> None:
        sim, st, table = self.sim, self.sim.store, self.sim.constraints
        st.goals, st.solved_positions = None, None
        if table.m == 0:
            return
        table.error[:] = np.nan
        weight = table.weights(sim.time_s, st.clip, st.clip_time_s)
        table.weight = weight
        if not np.any(weight > 0):
            table.held[:] = False
            return
        unconstrained = decode(st.poses, st.lengths)
        targets = target_points(table, unconstrained, st.posture)
        broken = (weight > 0) & ~np.all(np.isfinite(targets), axis=1)
        if broken.any():
            sim.report_disabled(np.flatnonzero(broken))
            table.enabled[broken] = False
            weight = np.where(broken, 0.0, weight)
            table.weight = weight
            targets[broken] = 0.0
        own = centres_of_mass(unconstrained.positions, st.segment_mass_kg, st.segment_com_fraction)
        given = np.isfinite(st.com_target_xy).all(axis=1)
        own[given, :2] = st.com_target_xy[given]
        goals = tick_goals(table, weight, targets, unconstrained, st.contact_weight,
                           st.com_control, own, st.posture,
                           sim.solver_settings.release_speed_m_s * sim.dt)
        table.held[:] = False
        active = np.flatnonzero(weight > 0)
        if goals is None:  # only areas the motion already keeps
            table.error[active] = constraint_errors(table, active, unconstrained, targets)
            return
        rows = goals.rows
        poses, _, solved = solve(st.poses.take(rows), st.lengths[rows], goals,
                                 st.segment_mass_kg[rows], st.segment_com_fraction[rows],
                                 sim.solver_settings, unconstrained.take(rows))
        st.poses = scatter(st.poses, rows, poses)
        user = goals.table_index >= 0
        table.held[goals.table_index[user]] = goals.held[user]
        # Every active constraint's error on the result (an area the motion already kept was
        # not a goal, but another constraint's move may have taken its point out).
        result = unconstrained
        for field in fields(DecodedPose):
            getattr(result, field.name)[rows] = getattr(solved, field.name)
        # Targets on the character's own body moved with it during the solve: read them again.
        targets = np.where((table.target_row == table.owner)[:, None]
                           & (table.target_kind != TARGET_WORLD)[:, None],
                           target_points(table, result, st.posture), targets)
        table.error[active] = constraint_errors(table, active, result, targets)
        st.com_desired[rows] = goals.com_desired
        st.goals, st.solved_positions = goals, solved.positions
