"""COMControl: the paper's ``adaptRoot()`` (§9): bring the centre of mass back.

For characters whose pose a constraint changed this tick (and whose COM control is on), the
root is translated horizontally so the whole-body centre of mass (de Leva segment masses of
each body) returns to where the motion had it before the constraints; feet in contact are kept
on their footprints (legs re-aimed) and the constraints are solved again after each move, a few
iterations, as the paper does inside the solver loop after the trunk.

Reads: store.poses, lengths, goals, com_desired, com_control, contact_weight, segment masses.
Writes: store.poses (root, legs, arms) of those characters.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ecs_anim.ground_adapt import adapt_to_ground
from ecs_anim.morphology import centres_of_mass, leg_length
from ecs_anim.normalized import SIDE_JOINTS, NormalizedPoses, decode
from ecs_anim.solver_shell import ArmGoals, solve_arms
from ecs_anim.system_base import System

ITERATIONS = 6
TOLERANCE_M = 1e-4
ANKLES = list(SIDE_JOINTS["ankle"])


class COMControl(System):
    def run(self, dt: float) -> None:
        st = self.sim.store
        goals = st.goals
        if not isinstance(goals, ArmGoals):
            return
        rows = np.flatnonzero(goals.rows & st.com_control)
        if rows.size == 0:
            return
        poses = st.poses.take(rows)
        lengths = st.lengths[rows]
        masses, fractions = st.segment_mass_kg[rows], st.segment_com_fraction[rows]
        desired = st.com_desired[rows, :2]
        weights = st.contact_weight[rows]
        sub_goals = goals.take(rows)
        leg = leg_length(lengths)
        decoded = decode(poses, lengths)
        feet = decoded.positions[:, ANKLES]  # where the feet are now: they stay
        for _ in range(ITERATIONS):
            com = centres_of_mass(decoded.positions, masses, fractions)
            error = desired - com[:, :2]
            if np.abs(error).max() < TOLERANCE_M:
                break
            root = poses.root_position.copy()
            root[:, :2] += error / leg[:, None]
            moved = replace(poses, root_position=root)
            moved_decoded = decode(moved, lengths)
            moved = adapt_to_ground(moved, lengths, feet, weights,
                                    moved_decoded.positions[:, 0, 2], decoded=moved_decoded)
            poses = solve_arms(moved, lengths, sub_goals)
            decoded = decode(poses, lengths)
        st.poses = _scatter(st.poses, rows, poses)


def _scatter(all_poses: NormalizedPoses, rows: np.ndarray, part: NormalizedPoses) -> NormalizedPoses:
    arrays = {}
    for name, value in all_poses.arrays().items():
        new = value.copy()
        new[rows] = getattr(part, name)
        arrays[name] = new
    return NormalizedPoses(**arrays)
