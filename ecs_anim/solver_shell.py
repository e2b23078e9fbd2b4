"""The constraint solver's shell: targets, priorities and weights in, new poses out.

ConstraintSolve calls :func:`solve_arms` once per tick; COMControl calls it again after each
root move (the paper's ``adaptRoot()`` sits inside the solver loop, after the trunk), so the
constraints stay met while the centre of mass is brought back. Pure functions over arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from .constraint_table import TARGET_WORLD, ConstraintTable, winners
from .normalized import SIDE_JOINTS, SIDE_LENGTHS, NormalizedPoses, decode
from .rotations import quat_from_matrix
from .solver import reach, swivel

F64 = NDArray[np.float64]
SHOULDERS, WRISTS = SIDE_JOINTS["shoulder"], SIDE_JOINTS["wrist"]
UPPER, FORE = SIDE_LENGTHS["upper_arm"], SIDE_LENGTHS["forearm"]


@dataclass
class ArmGoals:
    """Per character and arm, the constraint to meet this tick (-1: none).

    end, middle : (n, 2) indices into ``targets`` / ``weight`` (wrist, elbow).
    targets : (m, 3) world targets; weight : (m,) activation.
    """

    end: NDArray[np.int64]
    middle: NDArray[np.int64]
    targets: F64
    weight: F64
    base_arm_frame: F64  # (n, 2, 4) the motion's own arms, before any constraint
    base_arm_fraction: F64  # (n, 2)

    def take(self, rows: NDArray[np.int64]) -> ArmGoals:
        """The goals of some characters only (constraint indices stay valid)."""
        return ArmGoals(self.end[rows], self.middle[rows], self.targets, self.weight,
                        self.base_arm_frame[rows], self.base_arm_fraction[rows])

    @property
    def rows(self) -> NDArray[np.bool_]:
        """(n,) characters with anything to solve."""
        return np.any((self.end >= 0) | (self.middle >= 0), axis=1)


def arm_goals(table: ConstraintTable, poses: NormalizedPoses, time_s: float,
              reference_positions: F64) -> tuple[ArmGoals, NDArray[np.int64]]:
    """Targets and winning constraints for this tick; also the indices of constraints whose
    target is not finite (the caller switches them off and says so)."""
    weight = table.weights(time_s)
    targets = np.where((table.target_kind == TARGET_WORLD)[:, None], table.target_world,
                       reference_positions[table.target_row, table.target_joint])
    broken = (weight > 0) & ~np.all(np.isfinite(targets), axis=1)
    weight = np.where(broken, 0.0, weight)
    targets = np.where(broken[:, None], 0.0, targets)
    active = weight > 0
    n = poses.batch_shape[0]
    end = winners(table.owner, table.slot, table.priority, active & (table.role == 0), n, 2)
    middle = winners(table.owner, table.slot, table.priority, active & (table.role == 1), n, 2)
    return (ArmGoals(end, middle, targets, weight, poses.arm_frame.copy(),
                     poses.arm_fraction.copy()), np.flatnonzero(broken))


def solve_arms(poses: NormalizedPoses, lengths: F64, goals: ArmGoals) -> NormalizedPoses:
    """Meet the wrist goals (reach), then the elbow goals (swivel, keeping the wrist), each
    blended by its weight from the motion's own arm (so solving again, after the root moved,
    does not compound the blend). Only the arms change. Rows of ``poses``, ``lengths`` and
    ``goals`` match."""
    if not goals.rows.any():
        return poses
    poses = replace(poses, arm_frame=goals.base_arm_frame, arm_fraction=goals.base_arm_fraction)
    decoded = decode(poses, lengths)
    arm2world = decoded.arm2world.copy()
    fraction = poses.arm_fraction.copy()
    for slot in range(2):  # the two arms (limbs, not characters)
        rows = np.flatnonzero(goals.end[:, slot] >= 0)
        if rows.size:
            c = goals.end[rows, slot]
            wrist = decoded.positions[rows, WRISTS[slot]]
            goal = wrist + goals.weight[c, None] * (goals.targets[c] - wrist)
            arm2world[rows, slot], fraction[rows, slot], _ = reach(
                decoded.positions[rows, SHOULDERS[slot]], arm2world[rows, slot],
                lengths[rows, UPPER[slot]], lengths[rows, FORE[slot]], goal)
        rows = np.flatnonzero(goals.middle[:, slot] >= 0)
        if rows.size:
            c = goals.middle[rows, slot]
            arm2world[rows, slot] = swivel(decoded.positions[rows, SHOULDERS[slot]],
                                           arm2world[rows, slot], goals.targets[c], goals.weight[c])
    changed = (goals.end >= 0) | (goals.middle >= 0)
    arm2thorax = np.swapaxes(decoded.thorax2world[:, None], -1, -2) @ arm2world
    out = NormalizedPoses(**poses.arrays())
    out.arm_frame = np.where(changed[..., None], quat_from_matrix(arm2thorax), poses.arm_frame)
    out.arm_fraction = np.where(changed, fraction, poses.arm_fraction)
    return out
