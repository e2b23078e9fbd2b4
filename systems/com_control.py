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
from ecs_anim.normalized import SIDE_JOINTS, NormalizedPoses, decode, decode_legs
from ecs_anim.solver_shell import ArmGoals, solve_arms
from ecs_anim.system_base import System

ITERATIONS = 3
#: 1 / (share of body mass that moves with the root when both feet are planted, ~0.8).
ROOT_GAIN = 1.25
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
        decoded = decode(poses, lengths)
        feet = decoded.positions[:, ANKLES]  # where the feet are now: they stay
        com = centres_of_mass(decoded.positions, masses, fractions)
        error = st.com_desired[rows, :2] - com[:, :2]
        todo = np.arange(rows.size)
        for _ in range(ITERATIONS):
            # Only the characters still off their COM take another step (the set shrinks).
            todo = todo[np.abs(error[todo]).max(axis=1) >= TOLERANCE_M]
            if todo.size == 0:
                break
            part = poses.take(todo)
            part_lengths = lengths[todo]
            root = part.root_position.copy()
            # The legs' mass stays partly behind (feet planted): step past the error by the
            # share that does not follow the root, so one or two steps converge.
            root[:, :2] += error[todo] * ROOT_GAIN / leg_length(part_lengths)[:, None]
            moved = replace(part, root_position=root)
            legs = decode_legs(moved, part_lengths, part_lengths)
            moved = adapt_to_ground(moved, part_lengths, feet[todo], st.contact_weight[rows[todo]],
                                    legs.pelvis[:, 2], decoded=legs)
            part = solve_arms(moved, part_lengths, goals.take(rows[todo]))
            poses = _scatter(poses, todo, part)
            com = centres_of_mass(decode(part, part_lengths).positions, masses[todo], fractions[todo])
            error[todo] = st.com_desired[rows[todo], :2] - com[:, :2]
        st.poses = _scatter(st.poses, rows, poses)


def _scatter(all_poses: NormalizedPoses, rows: np.ndarray, part: NormalizedPoses) -> NormalizedPoses:
    arrays = {}
    for name, value in all_poses.arrays().items():
        new = value.copy()
        new[rows] = getattr(part, name)
        arrays[name] = new
    return NormalizedPoses(**arrays)
