"""ConstraintSolve: Cartesian constraints by priority on the analytic limbs (paper §9).

First cut: position constraints on the wrists (reach, the highest-priority active one per arm)
and elbows (swivel about the shoulder -> wrist axis, which keeps the wrist: fig. 11/13), each
blended by its activation weight (the solver shell is :mod:`ecs_anim.solver_shell`). Targets on
other characters are read from their posture of the previous tick (on the first tick, from this
tick's unsolved poses), so every character sees the same world whatever the order. Trunk/head
CCD, legs, distance/area constraints come with the rest of the constraint issue.

Reads: store.poses, lengths, positions (the previous tick's posture), segment masses; the
constraint table. Writes: store.poses (arms), store.com_desired (the centre of mass before
constraints, for COMControl), store.goals; table.enabled (a constraint whose target turns
non-finite is switched off, with one warning).
"""

from __future__ import annotations

from ecs_anim.morphology import centres_of_mass
from ecs_anim.normalized import decode
from ecs_anim.solver_shell import arm_goals, solve_arms
from ecs_anim.system_base import System


class ConstraintSolve(System):
    def run(self, dt: float) -> None:
        sim, st, table = self.sim, self.sim.store, self.sim.constraints
        st.goals = None
        if table.m == 0:
            return
        before = decode(st.poses, st.lengths)
        reference = before.positions if sim.tick == 0 else st.positions
        goals, broken = arm_goals(table, st.poses, sim.time_s, reference)
        if broken.size:
            sim.report_disabled(broken)
            table.enabled[broken] = False
        if not goals.rows.any():
            return
        st.com_desired = centres_of_mass(before.positions, st.segment_mass_kg,
                                         st.segment_com_fraction)
        st.goals = goals
        st.poses = solve_arms(st.poses, st.lengths, goals)
