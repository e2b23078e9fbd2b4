"""ConstraintSolve: every active constraint of every character, by priority (paper §9).

Gathers the store's arrays, calls the solver's tick (:func:`ecs_anim.solver_shell.constrain`:
targets, goals, the compiled solve :func:`ecs_anim.kernels.solve.solve` of the characters with
an active constraint, each constraint's error on the result) and writes the results back. The
activation weights run on simulation time, or on the clip time of constraints stored with a
motion; a point on another character is read from its posture of the previous tick (so every
character sees the same world whatever their order), a point on the same character from this
tick's pose. A constraint whose target is not finite is switched off with one warning.

Rows: characters with a Constraint component.
Reads: store.poses, lengths, posture (the previous tick's), contact_weight, clip, clip_time_s,
com_control, com_target_xy, segment_mass_kg, segment_com_fraction; the constraints table.
Writes: store.poses (solved characters), com_desired, goals, solved_positions; table.held;
table.enabled, table.weight, table.error (how far each active constraint is from being met on
the result, :func:`~ecs_anim.solver_shell.constraint_errors`; NaN while inactive).
"""

from __future__ import annotations

from ecs_anim.components import Constraint
from ecs_anim.kernels.decode import decode
from ecs_anim.kernels.solve import solve as solve  # re-exported: tests patch it here
from ecs_anim.solver_shell import constrain, scatter
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
        weight = table.weights(sim.time_s, st.clip, st.clip_time_s)
        settings = sim.solver_settings
        unconstrained = decode(st.poses, st.lengths) if (weight > 0).any() else None
        result = constrain(table, weight, st.poses, unconstrained, st.lengths,
                           st.contact_weight, st.com_control, st.com_target_xy, st.segment_mass_kg,
                           st.segment_com_fraction, st.posture, settings,
                           settings.release_speed_m_s * sim.dt, solve)
        if result.broken.size:
            sim.report_disabled(result.broken)
            table.enabled[result.broken] = False
        table.weight = result.weight
        table.error[:] = result.error
        table.held[:] = result.held
        if result.goals is None or result.poses is None or result.solved is None:
            return
        st.poses = scatter(st.poses, result.rows, result.poses)
        st.com_desired[result.rows] = result.goals.com_desired
        st.goals, st.solved_positions = result.goals, result.solved.positions
