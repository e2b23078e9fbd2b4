"""Every character's constraints, as one structure-of-arrays table (paper §5, DESIGN §5).

A constraint is ``{point, kind, chain, priority, activation}`` plus its target:

* kinds: ``position`` (the point on a target point), ``distance`` (the point at ``distance_m``
  from the target point; 0 is contact), ``area`` (keep the point inside, or outside, a box, a
  sphere or a half-space placed at the target point), ``orientation`` (a segment axis along a
  world direction, or looking at the target point);
* targets: a fixed world point, a point given by code (:meth:`ConstraintTable.set_targets`), or a
  body point (segment + fraction + offset) of a character. Another character's point is read
  from its posture of the previous tick (the posture every character had when this tick began:
  all characters see the same, consistent world, whatever their order); a point on the
  constrained character itself from its own pose of this tick before constraints (so two hands
  of one body meet without a tick of lag);
* chain: the groups (:data:`ecs_anim.core.body_points.GROUPS`) allowed to move for it, as a bit mask;
* activation: a ramp in simulation time, or for constraints stored with a motion, in the time of
  that clip while the character plays it (``clock`` = the clip's index in the bank).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.body_points import (
    ALLOWED_CHAIN,
    GROUP_INDEX,
    GROUPS,
    SEGMENTS,
    BodyPoint,
    body_point,
)
from ecs_anim.core.checks import found, is_integer, is_real, real_array, real_number
from ecs_anim.core.errors import UsageError
from ecs_anim.motion.constraints import Activation, ConstraintSpec, ramp_weight

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

KIND_POSITION, KIND_DISTANCE, KIND_AREA, KIND_ORIENTATION = range(4)
KIND_NAMES = {"position": KIND_POSITION, "distance": KIND_DISTANCE, "area": KIND_AREA,
              "orientation": KIND_ORIENTATION}
AREA_BOX, AREA_SPHERE, AREA_HALF_SPACE = 1, 2, 3
AREA_NAMES = {"box": AREA_BOX, "sphere": AREA_SPHERE, "half_space": AREA_HALF_SPACE}
TARGET_WORLD, TARGET_BODY = 0, 1
#: Segments whose orientation can be constrained: the distal limb segments (their axis only),
#: the head (any axis of its frame) and the thorax (spine_upper: any axis, moved by the trunk).
ORIENTABLE = {"hand_l", "hand_r", "foot_l", "foot_r", "head", "spine_upper"}
#: The default activation of :meth:`ConstraintTable.add`: on from the start, for good.
ALWAYS = Activation(0.0, 1e9)


def _is_point(value: object) -> bool:
    return isinstance(value, BodyPoint)


def _is_names(value: object) -> bool:
    """Whether ``value`` is a tuple or list of texts (a bare text is not)."""
    return isinstance(value, (tuple, list)) and all(isinstance(v, str) for v in value)


@dataclass(frozen=True)
class Area:
    """A restricted area, placed at its constraint's target point.

    ``box``: ``low_m``/``high_m`` corners relative to that point; ``sphere``: ``radius_m``;
    ``half_space``: ``normal`` (the allowed side is where the normal points). ``inside`` False
    keeps the point out of the area instead."""

    shape: str
    low_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    high_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    radius_m: float = 0.0
    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    inside: bool = True

    def __post_init__(self) -> None:
        if self.shape not in AREA_NAMES:
            raise UsageError(f"unknown area shape {self.shape!r}; shapes: {', '.join(AREA_NAMES)}")
        # Lists are welcome (an .nmo header is JSON): stored as 3-tuples of floats.
        for name in ("low_m", "high_m", "normal"):
            value = tuple(float(v) for v in getattr(self, name))
            if len(value) != 3:
                raise UsageError(f"area {name} must have 3 values, got {len(value)}")
            object.__setattr__(self, name, value)
        object.__setattr__(self, "radius_m", float(self.radius_m))
        values = self.low_m + self.high_m + self.normal + (self.radius_m,)
        if not all(np.isfinite(v) for v in values):
            raise UsageError("area values must be finite")
        if self.shape == "box" and any(lo > hi for lo, hi in zip(self.low_m, self.high_m, strict=False)):
            raise UsageError(f"box low_m {self.low_m} must be below high_m {self.high_m}")
        if self.shape == "sphere" and self.radius_m <= 0:
            raise UsageError("sphere radius_m must be > 0")
        if self.shape == "half_space" and np.linalg.norm(self.normal) < 1e-9:
            raise UsageError("half_space normal must not be zero")


@dataclass(frozen=True)
class Target:
    """Where a constraint aims: ``world_m`` (a fixed point, or the direction of an orientation
    constraint), or ``point`` on the character in store row ``row``."""

    world_m: tuple[float, float, float] | None = None
    row: int | None = None
    point: BodyPoint | None = None

    def __post_init__(self) -> None:
        if (self.world_m is None) == (self.row is None):
            raise UsageError("give either a world target or a character")
        if self.row is not None and self.point is None:
            raise UsageError("a character target needs the body point to aim at")
        if self.row is not None and not (is_integer(self.row) and _is_point(self.point)):
            raise UsageError(f"a character target is a store row and a BodyPoint, got "
                             f"{found(self.row)} and {found(self.point)}")
        if self.world_m is not None:
            x, y, z = real_array(self.world_m, (3,), "target_in_world")
            if not all(np.isfinite((x, y, z))):
                raise UsageError(f"target {self.world_m} must be finite")
            object.__setattr__(self, "world_m", (float(x), float(y), float(z)))


def _empty(dtype: type, *trailing: int) -> Callable[[], NDArray[Any]]:
    """A dataclass default factory: an empty column of ``dtype``, shape (0, *trailing)."""
    return lambda: np.zeros((0, *trailing), dtype)


@dataclass
class ConstraintTable:
    """m constraints, one row each (shapes (m,) unless given; metres, seconds).

    owner: store row; kind; segment (length index), fraction, offset (m, 3): the point; group,
    bone: where the point sits for the solver; chain: bit mask of groups allowed to move;
    priority; activation (m, 4) start, stop, ease in, ease out; clock: -1 simulation time, else
    the clip whose time drives the activation; target_kind; target_world (m, 3); target_row,
    target_segment, target_fraction, target_offset (m, 3): a body point target; distance_m;
    area_shape (0 none), area_low, area_high (m, 3), area_radius, area_normal (m, 3),
    area_inside; axis (m, 3) the segment-frame axis an orientation constraint turns; enabled
    (a constraint whose target went non-finite is switched off, with a warning); held: a sphere
    to stay out of kept its point off the motion's place in the last tick; error: each
    constraint's remaining error after the last tick (metres, or radians for orientation; NaN
    while inactive); weight: each constraint's activation weight in the last tick; names; uid:
    each constraint's id, given once and never reused (rows move when a character is removed,
    ids do not; they stay in increasing order), ``next_uid`` the next one.
    """

    owner: I64 = field(default_factory=_empty(np.int64))
    kind: I64 = field(default_factory=_empty(np.int64))
    segment: I64 = field(default_factory=_empty(np.int64))
    fraction: F64 = field(default_factory=_empty(np.float64))
    offset: F64 = field(default_factory=_empty(np.float64, 3))
    group: I64 = field(default_factory=_empty(np.int64))
    bone: I64 = field(default_factory=_empty(np.int64))
    chain: I64 = field(default_factory=_empty(np.int64))
    priority: F64 = field(default_factory=_empty(np.float64))
    activation: F64 = field(default_factory=_empty(np.float64, 4))
    clock: I64 = field(default_factory=_empty(np.int64))
    target_kind: I64 = field(default_factory=_empty(np.int64))
    target_world: F64 = field(default_factory=_empty(np.float64, 3))
    target_row: I64 = field(default_factory=_empty(np.int64))
    target_segment: I64 = field(default_factory=_empty(np.int64))
    target_fraction: F64 = field(default_factory=_empty(np.float64))
    target_offset: F64 = field(default_factory=_empty(np.float64, 3))
    distance_m: F64 = field(default_factory=_empty(np.float64))
    area_shape: I64 = field(default_factory=_empty(np.int64))
    area_low: F64 = field(default_factory=_empty(np.float64, 3))
    area_high: F64 = field(default_factory=_empty(np.float64, 3))
    area_radius: F64 = field(default_factory=_empty(np.float64))
    area_normal: F64 = field(default_factory=_empty(np.float64, 3))
    area_inside: NDArray[np.bool_] = field(default_factory=_empty(np.bool_))
    axis: F64 = field(default_factory=_empty(np.float64, 3))
    enabled: NDArray[np.bool_] = field(default_factory=_empty(np.bool_))
    held: NDArray[np.bool_] = field(default_factory=_empty(np.bool_))
    error: F64 = field(default_factory=_empty(np.float64))
    weight: F64 = field(default_factory=_empty(np.float64))
    names: list[str] = field(default_factory=list)
    uid: I64 = field(default_factory=_empty(np.int64))
    next_uid: int = 0

    @property
    def m(self) -> int:
        return int(self.owner.shape[0])

    def add(self, name: str, owner: int, kind: str, point: BodyPoint, target: Target,
            priority: float = 0.0, activation: Activation = ALWAYS,
            chain: tuple[str, ...] | None = None, distance_m: float = 0.0,
            area: Area | None = None, axis: tuple[float, float, float] = (0.0, 0.0, 1.0),
            clock: int = -1) -> int:
        """Append one constraint (load time), validated; raises ValueError naming ``name``.
        ``chain`` defaults to the point's own group. Returns its index."""
        def fail(message: str) -> ValueError:
            return ValueError(f"constraint {name!r}: {message}")

        if not isinstance(point, BodyPoint) or not isinstance(target, Target):
            raise fail(f"expected a BodyPoint and a Target, got {found(point)} and {found(target)}")
        if not isinstance(activation, Activation):
            raise fail(f"activation must be an Activation, got {found(activation)}")
        if area is not None and not isinstance(area, Area):
            raise fail(f"area must be an Area (or None), got {found(area)}")
        if not is_integer(clock):
            raise fail(f"clock must be a clip index (-1: simulation time), got {found(clock)}")
        if not isinstance(kind, str) or kind not in KIND_NAMES:
            raise fail(f"unknown kind {kind!r}; kinds: {', '.join(KIND_NAMES)}")
        if chain is not None and not _is_names(chain):
            raise fail(f"chain must be a list of body group names ({', '.join(GROUPS)}), got "
                       f"{found(chain)}")
        chain = (GROUPS[point.group],) if chain is None else tuple(chain)
        priority = real_number(priority, f"constraint {name!r}: priority")
        distance_m = real_number(distance_m, f"constraint {name!r}: distance_m")
        axis_array = real_array(axis, (3,), f"constraint {name!r}: axis")
        axis = (float(axis_array[0]), float(axis_array[1]), float(axis_array[2]))
        if not chain:
            raise fail("empty chain: name the body groups allowed to move "
                       f"({', '.join(GROUPS)})")
        unknown = [g for g in chain if g not in GROUP_INDEX]
        if unknown:
            raise fail(f"unknown chain group {unknown[0]!r}; groups: {', '.join(GROUPS)}")
        groups = {GROUP_INDEX[g] for g in chain}
        if point.group not in groups:
            raise fail(f"the chain {list(chain)} must include {GROUPS[point.group]!r}, the group "
                       f"of {point.name!r}")
        if not groups <= ALLOWED_CHAIN[point.group]:
            extra = sorted(GROUPS[g] for g in groups - ALLOWED_CHAIN[point.group])
            raise fail(f"{point.name!r} cannot be moved by {', '.join(extra)}: a point of "
                       f"{GROUPS[point.group]!r} can use "
                       f"{' and '.join(sorted(GROUPS[g] for g in ALLOWED_CHAIN[point.group]))}")
        if not np.isfinite(priority):
            raise fail("priority must be finite")
        if kind == "area" and area is None:
            raise fail("an area constraint needs its area")
        if kind != "area" and area is not None:
            raise fail("only an area constraint takes an area")
        if kind == "distance" and not (np.isfinite(distance_m) and distance_m >= 0):
            raise fail(f"distance_m must be >= 0, got {distance_m}")
        if kind == "orientation":
            if point.name not in ORIENTABLE:
                raise fail(f"the orientation of {point.name!r} cannot be constrained; "
                           f"segments: {', '.join(sorted(ORIENTABLE))}")
            if not all(np.isfinite(axis)) or np.linalg.norm(axis) < 1e-9:
                raise fail(f"axis {axis} must be a non-zero direction")
            if point.name not in ("head", "spine_upper") and not np.allclose(
                    np.asarray(axis) / np.linalg.norm(axis), (0.0, 0.0, 1.0)):
                raise fail(f"only the bone axis (0, 0, 1) of {point.name!r} can be oriented")
            if target.world_m is not None and np.linalg.norm(target.world_m) < 1e-9:
                raise fail("an orientation's world direction must not be zero")
        a = activation
        ar = area or Area("box")
        values = {
            "owner": owner, "kind": KIND_NAMES[kind], "segment": point.segment,
            "fraction": point.fraction, "offset": point.offset_m, "group": point.group,
            "bone": point.bone, "chain": sum(1 << g for g in groups), "priority": priority,
            "activation": (a.start_s, a.stop_s, a.ease_in_s, a.ease_out_s), "clock": clock,
            "target_kind": TARGET_WORLD if target.world_m is not None else TARGET_BODY,
            "target_world": target.world_m if target.world_m is not None else (0.0, 0.0, 0.0),
            "target_row": target.row if target.row is not None else 0,
            "target_segment": target.point.segment if target.point else 0,
            "target_fraction": target.point.fraction if target.point else 0.0,
            "target_offset": target.point.offset_m if target.point else (0.0, 0.0, 0.0),
            "distance_m": distance_m,
            "area_shape": AREA_NAMES[ar.shape] if area is not None else 0,
            "area_low": ar.low_m, "area_high": ar.high_m, "area_radius": ar.radius_m,
            "area_normal": tuple(np.asarray(ar.normal) / np.linalg.norm(ar.normal)),
            "area_inside": ar.inside,
            "axis": tuple(np.asarray(axis, dtype=float) / np.linalg.norm(axis)),
            "enabled": True, "held": False, "error": np.nan, "weight": 0.0, "uid": self.next_uid,
        }
        # Every new row is made before any column grows: a refused constraint leaves the table
        # as it was (its columns all of one length).
        new_rows = {}
        for key, value in values.items():
            current = getattr(self, key)
            row = np.asarray([value], dtype=current.dtype)
            if row.shape[1:] != current.shape[1:]:
                raise fail(f"{key} must have shape {current.shape[1:]}, got {row.shape[1:]}")
            new_rows[key] = row
        for key, row in new_rows.items():
            setattr(self, key, np.concatenate([getattr(self, key), row]))
        self.names.append(name)
        self.next_uid += 1
        return self.next_uid - 1

    def rows_of(self, uids: I64) -> I64:
        """The table rows of constraint ids (as :meth:`add` returned them), (k,); raises
        ValueError naming an id whose constraint was removed (with its character) or never was."""
        uids = np.asarray(uids, dtype=np.int64)
        if self.m == 0:
            lost = np.ones(uids.shape, bool)
            rows = np.zeros(uids.shape, np.int64)
        else:
            rows = np.minimum(np.searchsorted(self.uid, uids), self.m - 1)
            lost = self.uid[rows] != uids
        if np.any(lost):
            raise ValueError(f"constraint id {int(uids[np.argmax(lost)])} is not in the simulation "
                             "(removed with its character, or never added)")
        return rows

    def remove_character(self, row: int) -> list[str]:
        """Delete the constraints of store row ``row`` and those whose target is a point on it,
        and renumber the rows after it (the store deletes that row too). Returns the deleted
        constraints' names; the indices of the constraints after them move down."""
        gone = (self.owner == row) | ((self.target_kind == TARGET_BODY) & (self.target_row == row))
        names = [n for n, g in zip(self.names, gone, strict=False) if g]
        for key in self.__dataclass_fields__:
            if isinstance(getattr(self, key), np.ndarray):
                setattr(self, key, getattr(self, key)[~gone])
        self.names = [n for n, g in zip(self.names, gone, strict=False) if not g]
        self.owner[self.owner > row] -= 1
        self.target_row[(self.target_kind == TARGET_BODY) & (self.target_row > row)] -= 1
        return names

    def set_targets(self, uids: I64, targets_in_world: F64) -> None:
        """New world targets from code for constraints given by id: ``uids`` (k,),
        ``targets_in_world`` (k, 3), read at the next tick (a non-finite one switches its
        constraint off then, with a warning). Shapes and types are checked before anything is
        written (UsageError)."""
        ids = np.asarray(uids)
        if ids.ndim != 1 or not (ids.dtype.kind in "iu" or ids.size == 0):
            raise UsageError(f"uids must be constraint ids of shape (k,), got {found(uids)}")
        targets = real_array(targets_in_world, (ids.shape[0], 3), "targets_in_world")
        rows = self.rows_of(ids.astype(np.int64))
        self.target_kind[rows] = TARGET_WORLD
        self.target_world[rows] = targets
        self.enabled[rows] = True

    def weights(self, time_s: float, clip: I64 | None = None, clip_time_s: F64 | None = None) -> F64:
        """(m,) activation weight of every constraint (0 where disabled). Motion constraints
        (``clock >= 0``) follow their owner's clip time while it plays that clip: ``clip``,
        ``clip_time_s`` (n,) per character."""
        t = np.full(self.m, time_s)
        on_clip = self.clock >= 0
        if on_clip.any() and clip is not None and clip_time_s is not None:
            playing = clip[self.owner] == self.clock
            t = np.where(on_clip, np.where(playing, clip_time_s[self.owner], -np.inf), t)
        return np.where(self.enabled, ramp_weight(t, *self.activation.T), 0.0)


def winners(owner: I64, key: I64, priority: F64, active: NDArray[np.bool_],
            n_rows: int, n_keys: int) -> I64:
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


def add_stored(table: ConstraintTable, owner: int, spec: ConstraintSpec, name: str,
               clock: int = -1) -> int:
    """Add a constraint stored with a motion (its target, if any, a point of the same body) for
    the character in row ``owner``. Raises ValueError naming ``name`` if it is malformed."""
    p = spec.params
    try:
        body = body_point(spec.segment, spec.fraction, spec.offset_m,
                          segment=spec.kind == "orientation")
        target = Target(row=owner, point=body_point(
            str(p.get("target_point") or ""), p.get("target_fraction"),
            tuple(p.get("target_offset_m", (0.0, 0.0, 0.0))), as_target=True))
        area = Area(**p["area"]) if "area" in p else None
        chain = tuple(spec.chain) if spec.chain else None
        if chain is not None and not all(isinstance(g, str) for g in chain):
            raise ValueError(f"chain {spec.chain!r} must be a list of group names")
        return table.add(name, owner, spec.kind, body, target, spec.priority, spec.activation,
                         chain, float(p.get("distance_m", 0.0)), area,
                         tuple(p.get("axis", (0.0, 0.0, 1.0))), clock)
    except (TypeError, KeyError) as exc:
        raise ValueError(f"constraint {name!r}: malformed ({type(exc).__name__}: {exc})") from None
    except ValueError as exc:
        message = str(exc)
        raise ValueError(message if message.startswith("constraint ") else
                         f"constraint {name!r}: {message}") from None


def check_stored(specs: list[ConstraintSpec], duration_s: float) -> None:
    """Raise ValueError if a constraint stored with a motion of ``duration_s`` seconds is
    malformed or can never be active (it starts after the clip ends)."""
    scratch = ConstraintTable()
    for spec in specs:
        if spec.kind == "foot_contact":
            if spec.segment not in ("ankle_l", "ankle_r"):
                raise ValueError(f"foot contact {spec.name!r} on {spec.segment!r}: foot contacts "
                                 "are on ankle_l or ankle_r")
            continue
        add_stored(scratch, 0, spec, spec.name)
        if spec.activation.start_s > duration_s + 1e-9:
            raise ValueError(f"constraint {spec.name!r}: starts at {spec.activation.start_s:g} s, "
                             f"after the clip ends ({duration_s:g} s): it would never be active")


__all__ = ["SEGMENTS", "Area", "ConstraintTable", "Target", "add_stored", "check_stored", "is_integer",
           "is_real", "real_array", "real_number", "winners"]
