"""ConstraintSolve: Cartesian constraints by priority on the analytic limbs (paper §9).

First cut: position constraints on the wrists (reach, the highest-priority active one per arm)
and elbows (swivel about the shoulder -> wrist axis, which keeps the wrist: fig. 11/13), each
blended by its activation weight. Targets on other characters are read from their posture of the
previous tick (on the first tick, from this tick's unsolved poses), so every character sees the
same world whatever the order. Trunk/head CCD, legs, distance/area constraints and COM control
come with the rest of the constraint issue.

Reads: store.poses, lengths, positions (the previous tick's posture); the constraint table.
Writes: store.poses.arm_frame, arm_fraction; table.enabled (a constraint whose target turns
non-finite is switched off, with one warning).
"""

from __future__ import annotations

import numpy as np

from ecs_anim.constraint_table import TARGET_WORLD, winners
from ecs_anim.normalized import SIDE_JOINTS, SIDE_LENGTHS, decode
from ecs_anim.rotations import quat_from_matrix
from ecs_anim.solver import reach, swivel
from ecs_anim.system_base import System

SHOULDERS, ELBOWS, WRISTS = SIDE_JOINTS["shoulder"], SIDE_JOINTS["elbow"], SIDE_JOINTS["wrist"]
UPPER, FORE = SIDE_LENGTHS["upper_arm"], SIDE_LENGTHS["forearm"]


class ConstraintSolve(System):
    def run(self, dt: float) -> None:
        sim, st, table = self.sim, self.sim.store, self.sim.constraints
        if table.m == 0:
            return
        weight = table.weights(sim.time_s)
        decoded = decode(st.poses, st.lengths)
        reference = decoded.positions if sim.tick == 0 else st.positions
        targets = np.where((table.target_kind == TARGET_WORLD)[:, None], table.target_world,
                           reference[table.target_row, table.target_joint])
        broken = (weight > 0) & ~np.all(np.isfinite(targets), axis=1)
        if broken.any():
            sim.report_disabled(np.flatnonzero(broken))
            table.enabled[broken] = False
            weight = np.where(broken, 0.0, weight)
        active = weight > 0
        if not active.any():
            return
        n = st.n
        ends = winners(table.owner, table.slot, table.priority, active & (table.role == 0), n, 2)
        middles = winners(table.owner, table.slot, table.priority, active & (table.role == 1), n, 2)
        arm2world = decoded.arm2world.copy()
        fraction = st.poses.arm_fraction.copy()
        for slot in range(2):  # the two arms (limbs, not characters)
            rows = np.flatnonzero(ends[:, slot] >= 0)
            if rows.size:
                c = ends[rows, slot]
                shoulder = decoded.positions[rows, SHOULDERS[slot]]
                wrist = decoded.positions[rows, WRISTS[slot]]
                goal = wrist + weight[c, None] * (targets[c] - wrist)
                arm2world[rows, slot], fraction[rows, slot], _ = reach(
                    shoulder, arm2world[rows, slot], st.lengths[rows, UPPER[slot]],
                    st.lengths[rows, FORE[slot]], goal)
            rows = np.flatnonzero(middles[:, slot] >= 0)
            if rows.size:
                c = middles[rows, slot]
                arm2world[rows, slot] = swivel(decoded.positions[rows, SHOULDERS[slot]],
                                               arm2world[rows, slot], targets[c], weight[c])
        changed = (ends >= 0) | (middles >= 0)
        thorax2world = decoded.thorax2world[:, None]
        arm2thorax = np.swapaxes(thorax2world, -1, -2) @ arm2world
        st.poses.arm_frame = np.where(changed[..., None], quat_from_matrix(arm2thorax),
                                      st.poses.arm_frame)
        st.poses.arm_fraction = np.where(changed, fraction, st.poses.arm_fraction)
