"""What the viewer reads of the constraints: a few small accessors, nothing else.

The constraint solver (``ecs_anim.constraint_table``) is changing; everything the viewer needs
from it goes through the functions here, so a change of the table touches this file only.
Read-only (STYLE 8).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..constraint_table import ConstraintTable
from ..simulation import Simulation
from ..skeleton import JOINT_INDEX

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class ConstraintMarks:
    """The constraints to draw for the posture in the store (m of them, active ones only).

    target (m, 3) and point (m, 3): world metres, where the constrained joint should be and
    where it is; priority (m,); weight (m,) activation in (0, 1].
    """

    target: F64
    point: F64
    priority: F64
    weight: F64

    @property
    def error_m(self) -> F64:
        """(m,) distance from each constrained point to its target, metres."""
        return np.asarray(np.linalg.norm(self.target - self.point, axis=-1), dtype=np.float64)


def posture_time_s(sim: Simulation) -> float:
    """Simulation time of the posture now in the store (the last tick stepped)."""
    return max(sim.tick - 1, 0) * sim.dt


def _joint_of_constraint(table: ConstraintTable) -> NDArray[np.int64]:
    """(m,) index of the constrained joint of every constraint of the table."""
    from ..constraint_table import POINTS

    lookup = {slot_role: JOINT_INDEX[joint] for joint, slot_role in POINTS.items()}
    slots = np.asarray(table.slot, dtype=np.int64)
    roles = np.asarray(table.role, dtype=np.int64)
    return np.array([lookup.get((int(s), int(r)), 0) for s, r in zip(slots, roles)], dtype=np.int64)


def constraint_marks(sim: Simulation) -> ConstraintMarks:
    """The active constraints' targets and constrained points for the posture in the store.

    Targets on another character are read from that character's current posture.
    """
    from ..constraint_table import TARGET_WORLD

    table, positions = sim.constraints, sim.store.positions
    if table.m == 0 or positions.shape[0] == 0:
        empty = np.zeros((0, 3))
        return ConstraintMarks(empty, empty, np.zeros(0), np.zeros(0))
    weight = np.asarray(table.weights(posture_time_s(sim)), dtype=np.float64)
    target = np.where((table.target_kind == TARGET_WORLD)[:, None], table.target_world,
                      positions[table.target_row, table.target_joint])
    point = positions[table.owner, _joint_of_constraint(table)]
    keep = (weight > 0) & np.all(np.isfinite(target), axis=1) & np.all(np.isfinite(point), axis=1)
    return ConstraintMarks(target[keep], point[keep], np.asarray(table.priority)[keep], weight[keep])


def max_constraint_error_m(marks: ConstraintMarks) -> float | None:
    """Largest distance to target among fully active constraints (weight 1), or None."""
    full = marks.weight >= 1.0 - 1e-9
    return float(marks.error_m[full].max()) if full.any() else None


@dataclass(frozen=True)
class RestrictedAreas:
    """Restricted areas to draw, as spheres: centre (k, 3) metres, radius (k,) metres.

    Empty until the constraint table holds area constraints (the solver issue adds them).
    """

    centre: F64
    radius: F64


def restricted_areas(sim: Simulation) -> RestrictedAreas:
    """Restricted areas (sphere-shaped) of the constraint table, if it has any.

    Reads the table's optional ``area_centre`` (k, 3) and ``area_radius`` (k,) arrays; a table
    without them has no areas.
    """
    table = sim.constraints
    centre = getattr(table, "area_centre", None)
    radius = getattr(table, "area_radius", None)
    if centre is None or radius is None:
        return RestrictedAreas(np.zeros((0, 3)), np.zeros(0))
    return RestrictedAreas(np.asarray(centre, dtype=np.float64).reshape(-1, 3),
                           np.asarray(radius, dtype=np.float64).reshape(-1))
