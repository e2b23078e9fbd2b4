"""What the viewer reads of the constraints: a few small accessors, nothing else.

The constraint table (``ecs_anim.motion.constraint_table``) is being extended by the solver work; the
viewer reads it only here, and copes with both of its shapes: the first cut (wrist/elbow
points by ``slot``/``role``, targets on another character's joint) and the full one (body
points ``segment``/``fraction``/``offset``, constraint ``kind``, restricted ``area_*`` columns,
per-constraint ``error``). Read-only (STYLE 8).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.skeleton import BONE_JOINTS, JOINT_INDEX
from ecs_anim.runtime.simulation import Simulation

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: Kinds and area shapes of the full table (``constraint_table.KIND_*``, ``AREA_*``).
KIND_AREA, KIND_ORIENTATION = 2, 3
AREA_BOX, AREA_SPHERE, AREA_HALF_SPACE = 1, 2, 3
TARGET_WORLD = 0

_SEG_PROXIMAL = np.array([max(a, 0) for a, _ in BONE_JOINTS])
_SEG_DISTAL = np.array([max(b, 0) for _, b in BONE_JOINTS])


@dataclass(frozen=True)
class ConstraintMarks:
    """Point constraints to draw for the posture in the store (m of them, active ones only).

    target (m, 3) and point (m, 3): world metres, where the constrained point should be and
    where it is; priority (m,); weight (m,) activation in (0, 1]; error_m (m,) how far each is
    from being met (the solver's own figure where the table keeps one); uid (m,) each one's id
    (for :meth:`Simulation.set_target`); in_world (m,) bool whether its target is a world point
    (which the viewer lets the user drag) rather than a point on a body.
    """

    target: F64
    point: F64
    priority: F64
    weight: F64
    error_m: F64
    uid: I64 = field(default_factory=lambda: np.zeros(0, np.int64))
    in_world: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, bool))


@dataclass(frozen=True)
class RestrictedAreas:
    """Active restricted areas, world metres: spheres ``sphere_centre`` (a, 3) and
    ``sphere_radius`` (a,); boxes ``box_low``/``box_high`` (b, 3) corners; half-spaces
    ``plane_point``/``plane_normal`` (c, 3) (the allowed side is where the normal points)."""

    sphere_centre: F64
    sphere_radius: F64
    box_low: F64
    box_high: F64
    plane_point: F64
    plane_normal: F64

    @staticmethod
    def none() -> RestrictedAreas:
        e3 = np.zeros((0, 3))
        return RestrictedAreas(e3, np.zeros(0), e3, e3, e3, e3)


def _weights(sim: Simulation, table: Any) -> F64:
    st = sim.store
    try:  # the full table: motion constraints follow their clip's time
        w = table.weights(sim.posture_time_s, st.clip, st.clip_time_s)
    except TypeError:
        w = table.weights(sim.posture_time_s)
    return np.asarray(w, dtype=np.float64)


def _body_points(positions: F64, rows: I64, segment: I64, fraction: F64) -> F64:
    """Points on bones (offsets not applied): (k, 3) world metres."""
    a, b = positions[rows, _SEG_PROXIMAL[segment]], positions[rows, _SEG_DISTAL[segment]]
    return np.asarray(a + np.asarray(fraction)[:, None] * (b - a), dtype=np.float64)


def _constrained_points(table: Any, positions: F64) -> F64:
    """(m, 3) where each constraint's point is now."""
    owner = np.asarray(table.owner, dtype=np.int64)
    if hasattr(table, "segment") and hasattr(table, "fraction"):
        return _body_points(positions, owner, np.asarray(table.segment, np.int64), table.fraction)
    from ecs_anim.motion import constraint_table

    points: dict[str, tuple[int, int]] = getattr(constraint_table, "POINTS", {})
    lookup = {slot_role: JOINT_INDEX[joint] for joint, slot_role in points.items()}
    joints = np.array([lookup.get((int(s), int(r)), 0) for s, r in zip(table.slot, table.role, strict=False)],
                      dtype=np.int64)
    return np.asarray(positions[owner, joints], dtype=np.float64)


def _targets(table: Any, positions: F64) -> F64:
    """(m, 3) each constraint's target point (world, or read from a character's posture)."""
    rows = np.asarray(table.target_row, dtype=np.int64)
    if hasattr(table, "target_segment"):
        on_body = _body_points(positions, rows, np.asarray(table.target_segment, np.int64),
                               table.target_fraction)
    else:
        on_body = positions[rows, np.asarray(table.target_joint, np.int64)]
    world = np.asarray(table.target_world, dtype=np.float64)
    return np.asarray(np.where((np.asarray(table.target_kind) == TARGET_WORLD)[:, None], world,
                               on_body), dtype=np.float64)


def _kinds(table: Any) -> I64:
    return np.asarray(getattr(table, "kind", np.zeros(table.m, np.int64)), dtype=np.int64)


def _owner_shown(table: Any, shown: NDArray[np.bool_] | None) -> NDArray[np.bool_]:
    """(m,) whether each constraint's owner is drawn (``shown`` (n,) per store row; None: all)."""
    if shown is None:
        return np.ones(table.m, bool)
    return np.asarray(shown[np.asarray(table.owner, dtype=np.int64)], dtype=bool)


def constraint_marks(sim: Simulation, shown: NDArray[np.bool_] | None = None) -> ConstraintMarks:
    """The active point constraints (not orientations or areas) for the posture in the store,
    of the characters ``shown`` (n,) per store row (None: every character)."""
    table, positions = sim.constraints, sim.store.positions
    if table.m == 0 or positions.shape[0] != sim.store.n or positions.shape[0] == 0:
        e3 = np.zeros((0, 3))
        return ConstraintMarks(e3, e3, np.zeros(0), np.zeros(0), np.zeros(0))
    weight = _weights(sim, table)
    target, point = _targets(table, positions), _constrained_points(table, positions)
    kind = _kinds(table)
    error = np.linalg.norm(target - point, axis=-1)
    if hasattr(table, "error"):  # as ConstraintSolve measured it on its result (any kind)
        solver_error = np.asarray(table.error, dtype=np.float64)
        error = np.where(np.isfinite(solver_error), solver_error, error)
    keep = ((weight > 0) & (kind != KIND_ORIENTATION) & (kind != KIND_AREA) & _owner_shown(table, shown)
            & np.all(np.isfinite(target), axis=1) & np.all(np.isfinite(point), axis=1))
    uid = np.asarray(getattr(table, "uid", np.arange(table.m)), dtype=np.int64)
    in_world = np.asarray(table.target_kind) == TARGET_WORLD
    return ConstraintMarks(target[keep], point[keep], np.asarray(table.priority)[keep],
                           weight[keep], error[keep], uid[keep], in_world[keep])


def max_constraint_error_m(sim: Simulation) -> float | None:
    """Largest error (m) among the fully active constraints (weight 1) of every kind measured
    in metres (all but orientations), as ConstraintSolve measured it; None without any."""
    table: Any = sim.constraints
    if table.m == 0 or not hasattr(table, "error"):
        return None
    error = np.asarray(table.error, dtype=np.float64)
    full = ((_weights(sim, table) >= 1.0 - 1e-9) & (_kinds(table) != KIND_ORIENTATION)
            & np.isfinite(error))
    return float(error[full].max()) if full.any() else None


def restricted_areas(sim: Simulation, shown: NDArray[np.bool_] | None = None) -> RestrictedAreas:
    """The active restricted areas of the characters ``shown`` (n,) per store row (None: every
    character), placed at their targets (none with a table that has no ``area_shape`` column)."""
    table: Any = sim.constraints
    positions = sim.store.positions
    if (table.m == 0 or not hasattr(table, "area_shape") or positions.shape[0] != sim.store.n
            or positions.shape[0] == 0):
        return RestrictedAreas.none()
    active = (_weights(sim, table) > 0) & (_kinds(table) == KIND_AREA) & _owner_shown(table, shown)
    if not active.any():
        return RestrictedAreas.none()
    anchor = _targets(table, positions)
    shape = np.asarray(table.area_shape, dtype=np.int64)
    s, b, h = (active & (shape == k) for k in (AREA_SPHERE, AREA_BOX, AREA_HALF_SPACE))
    return RestrictedAreas(anchor[s], np.asarray(table.area_radius, np.float64)[s],
                           anchor[b] + np.asarray(table.area_low, np.float64)[b],
                           anchor[b] + np.asarray(table.area_high, np.float64)[b],
                           anchor[h], np.asarray(table.area_normal, np.float64)[h])


def unreachable_uids(sim: Simulation) -> frozenset[int]:
    """The constraints (ids) whose bodies cannot reach their targets, by the simulation's last
    feasibility estimate (``Simulation.unreachable``); none for a table without the full
    columns the estimate reads."""
    if not hasattr(sim.constraints, "clock"):
        return frozenset()
    return sim.unreachable()
