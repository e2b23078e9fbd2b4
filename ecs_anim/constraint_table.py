"""Scenario and code constraints of all characters, as one structure-of-arrays table.

First cut of the constraint issue: position constraints on the arms' analytic limbs, the wrist
(solved by reaching, highest priority first) and the elbow (solved by swivelling the arm about
its shoulder -> wrist axis, so a higher-priority wrist constraint is kept: paper fig. 11 and 13).
Targets are a fixed world point, a point given by code (:meth:`ConstraintTable.set_target`), or
a joint of another character read from that character's posture of the previous tick (the
posture every character had when this tick began: all characters see the same, consistent
world, whatever their order).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .constraints import Activation, ramp_weight
from .skeleton import JOINT_INDEX

F64 = NDArray[np.float64]

#: Constrained points supported so far: joint -> (limb slot, role). Slots: 0 arm_l, 1 arm_r;
#: roles: 0 the limb's end (wrist), 1 its middle joint (elbow).
POINTS: dict[str, tuple[int, int]] = {
    "wrist_l": (0, 0), "wrist_r": (1, 0), "elbow_l": (0, 1), "elbow_r": (1, 1),
}
LIMBS = ("arm_l", "arm_r")
TARGET_WORLD, TARGET_CHARACTER = 0, 1


@dataclass
class ConstraintTable:
    """m constraints. owner (m,) store row; slot (m,), role (m,) see :data:`POINTS`;
    priority (m,); activation (m, 4) start, stop, ease in, ease out (s, simulation time);
    target_kind (m,); target_world (m, 3) metres; target_row (m,), target_joint (m,) for a
    point on another character; enabled (m,) (a constraint whose target went non-finite is
    switched off, with a warning); names (m,) for messages."""

    owner: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    slot: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    role: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    priority: F64 = field(default_factory=lambda: np.zeros(0))
    activation: F64 = field(default_factory=lambda: np.zeros((0, 4)))
    target_kind: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    target_world: F64 = field(default_factory=lambda: np.zeros((0, 3)))
    target_row: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    target_joint: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    enabled: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, bool))
    names: list[str] = field(default_factory=list)

    @property
    def m(self) -> int:
        return int(self.owner.shape[0])

    def add(self, name: str, owner: int, point: str, priority: float, activation: Activation,
            target_world: tuple[float, float, float] | None = None,
            target_row: int | None = None, target_point: str | None = None) -> int:
        """Append one constraint (load time). Exactly one target: a world point or another
        character's joint. Returns its index."""
        if point not in POINTS:
            raise ValueError(f"constraint {name!r}: point {point!r} is not supported yet; "
                             f"supported: {', '.join(POINTS)}")
        if (target_world is None) == (target_row is None):
            raise ValueError(f"constraint {name!r}: give either a world target or a character")
        if target_row is not None and target_point is None:
            raise ValueError(f"constraint {name!r}: a character target needs the joint to aim at")
        if target_point is not None and target_point not in JOINT_INDEX:
            raise ValueError(f"constraint {name!r}: unknown joint {target_point!r}")
        slot, role = POINTS[point]
        a = activation
        row = {
            "owner": owner, "slot": slot, "role": role, "priority": priority,
            "activation": (a.start_s, a.stop_s, a.ease_in_s, a.ease_out_s),
            "target_kind": TARGET_WORLD if target_world is not None else TARGET_CHARACTER,
            "target_world": target_world if target_world is not None else (0.0, 0.0, 0.0),
            "target_row": target_row if target_row is not None else 0,
            "target_joint": JOINT_INDEX[target_point] if target_point else 0,
            "enabled": True,
        }
        for key, value in row.items():
            current = getattr(self, key)
            setattr(self, key, np.concatenate([current, np.asarray([value], dtype=current.dtype)]))
        self.names.append(name)
        return self.m - 1

    def set_target(self, index: int, target_in_world: tuple[float, float, float]) -> None:
        """Give a constraint a new world target from code (read at the next tick)."""
        self.target_kind[index] = TARGET_WORLD
        self.target_world[index] = target_in_world
        self.enabled[index] = True

    def weights(self, time_s: float) -> F64:
        """(m,) activation weight of every constraint at ``time_s`` (0 where disabled)."""
        return np.where(self.enabled, ramp_weight(time_s, *self.activation.T), 0.0)


def winners(owner: NDArray[np.int64], key: NDArray[np.int64], priority: F64, active: NDArray[np.bool_],
            n_rows: int, n_keys: int) -> NDArray[np.int64]:
    """For every (row, key), the index of the active constraint with the highest priority, or -1.

    Ties go to the constraint added last. Returns (n_rows, n_keys) indices into the table.
    """
    out = np.full((n_rows, n_keys), -1, dtype=np.int64)
    candidates = np.flatnonzero(active)
    if candidates.size == 0:
        return out
    # Sort by priority then insertion: assigning in that order leaves the best in place.
    order = candidates[np.lexsort((candidates, priority[candidates]))]
    flat = owner[order] * n_keys + key[order]
    # np.unique on the reversed order keeps the last (best) occurrence of each cell.
    cells, first_in_reversed = np.unique(flat[::-1], return_index=True)
    out.reshape(-1)[cells] = order[::-1][first_in_reversed]
    return out
