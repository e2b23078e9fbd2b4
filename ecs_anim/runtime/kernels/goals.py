"""The compiled goals of a tick and the constraints' errors (ConstraintSolve's gather).

:func:`tick_goals`, :func:`constraint_errors` and :func:`errors_on_result` mirror
:func:`ecs_anim.solver.goals.tick_goals`, :func:`ecs_anim.solver.goals.constraint_errors` and
:func:`ecs_anim.solver.goals.errors_on_result` (same arguments, same results to 1e-9 m; the
numpy functions stay as the reference the tests compare these with). The per-constraint work
(its point, its goal from the target: a distance, an area's allowed region, a direction; the
release of a point a sphere held; the activation ramp's blend) runs compiled over the active
constraints, laid out by character, each character's two feet after its own goals, in one pass
(:func:`goal_layout_rows`); which characters the active constraints belong to, and the areas
the motion already keeps (rarely any) dropped after, are a few numpy calls. ConstraintSolve
keeps that layout from tick to tick while the same constraints are active
(:class:`GoalLayouts`): the kernel then writes each goal and its weight, not the columns that
stay the same.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.body_points import LEG_L
from ecs_anim.core.normalized import DecodedPose
from ecs_anim.motion.constraint_table import (
    AREA_BOX,
    AREA_HALF_SPACE,
    AREA_SPHERE,
    KIND_AREA,
    KIND_DISTANCE,
    KIND_ORIENTATION,
    TARGET_WORLD,
    ConstraintTable,
)
from ecs_anim.runtime.kernels import LIGHT_ROWS_PER_THREAD, over_chunks
from ecs_anim.runtime.kernels.decode import DecodedArrays
from ecs_anim.runtime.kernels.solve_points import (
    Tables,
    plain_point,
    point_position,
    segment_frame,
    tables,
)
from ecs_anim.runtime.kernels.vec import (
    F64,
    Vec3,
    add,
    add_scaled,
    dot,
    jit,
    load3,
    norm,
    normalize,
    rotation_toward,
    scale,
    store3,
    sub,
    to_world,
)
from ecs_anim.solver.capsules import CAPSULE_JOINTS, CAPSULE_SPAN, RADIUS_WEIGHTS, SEGMENT_CAPSULE
from ecs_anim.solver.goals import CONTACT_PRIORITY, TickGoals, other_surface_rows

I64 = NDArray[np.int64]
B8 = NDArray[np.bool_]
TABLES = tables()


@jit(nogil=True)
def weight_rows(time_s: float, on_clip: bool, clip: I64, clip_time_s: F64, owner: I64,
                clock: I64, enabled: B8, activation: F64, out: F64) -> None:
    """Mirrors :meth:`ecs_anim.motion.constraint_table.ConstraintTable.weights` (with
    :func:`ecs_anim.motion.constraints.ramp_weight`, smooth) into ``out`` (m,), bit for bit:
    each constraint's time ``time_s``, or with ``on_clip`` for one with a ``clock`` its owner's
    ``clip_time_s`` while the owner plays that ``clip`` (else -inf); numpy's ``minimum`` (the
    second of equal values, NaN from either) and ``clip`` (NaN kept) written out."""
    for i in range(out.shape[0]):
        if not enabled[i]:
            out[i] = 0.0
            continue
        t = time_s
        if on_clip and clock[i] >= 0:
            c = owner[i]
            t = clip_time_s[c] if clip[c] == clock[i] else -math.inf
        start, stop = activation[i, 0], activation[i, 1]
        ease_in, ease_out = activation[i, 2], activation[i, 3]
        if ease_in > 0:
            up = (t - start) / (ease_in if ease_in >= 1e-12 else 1e-12)
        else:
            up = 1.0 if t >= start else 0.0
        if ease_out > 0:
            down = (stop - t) / (ease_out if ease_out >= 1e-12 else 1e-12)
        else:
            down = 1.0 if t <= stop else 0.0
        x = up if (up < down or math.isnan(up)) else down
        if x < 0.0:
            x = 0.0
        elif x > 1.0:
            x = 1.0
        out[i] = x * x * x * (x * (6.0 * x - 15.0) + 10.0)


def weights(table: ConstraintTable, time_s: float, clip: I64 | None = None,
            clip_time_s: F64 | None = None) -> F64:
    """Compiled ``table.weights(time_s, clip, clip_time_s)`` (the same result, bit for bit)."""
    out = np.empty(table.m)
    on_clip = clip is not None and clip_time_s is not None
    weight_rows(float(time_s), on_clip,
                np.ascontiguousarray(clip if on_clip else np.zeros(0, np.int64), dtype=np.int64),
                np.ascontiguousarray(clip_time_s if on_clip else np.zeros(0), dtype=np.float64),
                np.ascontiguousarray(table.owner, dtype=np.int64),
                np.ascontiguousarray(table.clock, dtype=np.int64),
                np.ascontiguousarray(table.enabled, dtype=np.bool_),
                np.ascontiguousarray(table.activation, dtype=np.float64), out)
    return out


class Codes(NamedTuple):
    """The constraint table's codes the kernels branch on (passed as an argument: numba's cache
    would keep a module constant of another file as it was when compiled)."""

    kind_distance: int
    kind_area: int
    kind_orientation: int
    area_box: int
    area_sphere: int
    area_half_space: int
    target_world: int
    leg_l: int  # the left leg's group (the right one's is next)


CODES = Codes(KIND_DISTANCE, KIND_AREA, KIND_ORIENTATION, AREA_BOX, AREA_SPHERE, AREA_HALF_SPACE,
              TARGET_WORLD, LEG_L)


class Columns(NamedTuple):
    """The :class:`~ecs_anim.motion.constraint_table.ConstraintTable` columns the kernels read (same
    names; (m,) or (m, 3))."""

    owner: I64
    kind: I64
    segment: I64
    fraction: F64
    offset: F64
    group: I64
    bone: I64
    chain: I64
    priority: F64
    target_kind: I64
    distance_m: F64
    area_shape: I64
    area_low: F64
    area_high: F64
    area_radius: F64
    area_normal: F64
    area_inside: B8
    axis: F64
    held: B8


def columns(table: ConstraintTable) -> Columns:
    """The table's columns as the kernels take them (the arrays themselves when already
    C-contiguous of the right type)."""
    return Columns(*(np.ascontiguousarray(getattr(table, name)) for name in Columns._fields))


class GoalArrays(NamedTuple):
    """The k goals of :class:`~ecs_anim.solver.goals.TickGoals` the layout writes (same names
    and shapes: (k,), (k, 3); footprint and in_contact (r, 2, 3), (r, 2); com_desired (r, 3),
    com_on (r,))."""

    owner: I64
    table_index: I64
    orientation: B8
    group: I64
    bone: I64
    segment: I64
    fraction: F64
    offset: F64
    chain: I64
    priority: F64
    goal: F64
    weight: F64
    axis: F64
    held: B8
    footprint: F64
    in_contact: B8
    com_desired: F64
    com_on: B8


@jit(inline="always")
def area_goal(cols: Columns, i: int, point: Vec3, anchor: Vec3, side: Vec3, codes: Codes) -> Vec3:
    """Mirrors ``ecs_anim.solver.goals._area_goal`` for constraint ``i``: the nearest point of
    its allowed region to ``point``, the area sitting at ``anchor``; a point inside an area it
    must leave goes out on the side of ``side``."""
    shape, inside = cols.area_shape[i], cols.area_inside[i]
    rel = sub(point, anchor)
    rel_side = sub(side, anchor)
    if shape == codes.area_box:
        low, high = load3(cols.area_low[i]), load3(cols.area_high[i])
        if inside:  # clamp into the box
            return add(anchor, (min(max(rel[0], low[0]), high[0]),
                                min(max(rel[1], low[1]), high[1]),
                                min(max(rel[2], low[2]), high[2])))
        if not (low[0] < rel[0] < high[0] and low[1] < rel[1] < high[1]
                and low[2] < rel[2] < high[2]):
            return add(anchor, rel)
        # Out through the face nearest the side point (the first of equal ones, as argmin).
        face, gap = 0, rel_side[0] - low[0]
        for f in range(1, 6):
            a = f % 3
            g = rel_side[a] - low[a] if f < 3 else high[a] - rel_side[a]
            if g < gap:
                face, gap = f, g
        a = face % 3
        level = low[a] if face < 3 else high[a]
        out = (level if a == 0 else rel[0], level if a == 1 else rel[1],
               level if a == 2 else rel[2])
        return add(anchor, out)
    if shape == codes.area_sphere:
        distance = norm(rel)
        radius = cols.area_radius[i]
        # Left on the side point's side; its far side not reached through it.
        way = sub(rel, rel_side)
        along = min(max(-dot(rel_side, way) / max(dot(way, way), 1e-18), 0.0), 1.0)
        nearest_on_way = norm(add_scaled(rel_side, way, along))
        leave = not inside and (distance < radius or nearest_on_way < radius)
        toward = rel_side if leave and norm(rel_side) > 1e-12 else rel
        toward_len = norm(toward)
        direction = scale(toward, 1.0 / max(toward_len, 1e-12)) if toward_len > 1e-12 \
            else (0.0, 0.0, 1.0)
        if inside:
            length = min(distance, radius)
        else:
            length = radius if leave else distance
        return add(anchor, (direction[0] * length, direction[1] * length,
                            direction[2] * length))
    if shape == codes.area_half_space:
        sign = 1.0 if inside else -1.0
        n = load3(cols.area_normal[i])
        normal = (n[0] * sign, n[1] * sign, n[2] * sign)
        below = min(dot(rel, normal), 0.0)
        return add(anchor, sub(rel, (below * normal[0], below * normal[1], below * normal[2])))
    return add(anchor, rel)


@jit(inline="always")
def finite_or(a: Vec3, b: Vec3) -> Vec3:
    """``a``, each element that is not finite taken from ``b``."""
    return (a[0] if math.isfinite(a[0]) else b[0], a[1] if math.isfinite(a[1]) else b[1],
            a[2] if math.isfinite(a[2]) else b[2])


@jit(inline="always")
def constraint_goal(i: int, cols: Columns, weight: F64, targets: F64, dec: DecodedArrays,
                    previous: DecodedArrays, has_previous: bool, max_release_m: float, t: Tables,
                    codes: Codes) -> tuple[Vec3, float, bool]:
    """The goal of the active constraint ``i`` (``weight`` (m,), ``targets`` (m, 3)): its
    weighted goal (a unit direction for an orientation), its weight (0: an area the motion
    already keeps) and whether a sphere keeps its point off the motion's place. ``dec`` this
    tick's decoded pose of every character, ``previous`` the last tick's posture (read only
    with ``has_previous``). Mirrors the per-constraint part of
    :func:`ecs_anim.solver.goals.tick_goals`."""
    c = cols.owner[i]
    segment, fraction, offset = cols.segment[i], cols.fraction[i], load3(cols.offset[i])
    p0 = point_position(dec, c, segment, fraction, offset, t)
    kind = cols.kind[i]
    # Where the point was at the last tick (a distance's side, an area's way in), read only
    # for those (the last posture is cold memory); none for this point (a character added
    # since, a frozen pose): the motion's side.
    was = p0
    if has_previous and (kind == codes.kind_distance or kind == codes.kind_area):
        was = finite_or(point_position(previous, c, segment, fraction, offset, t), p0)
    target = load3(targets[i])
    goal = target
    if kind == codes.kind_distance:
        away = sub(was, target)
        away_len = norm(away)
        away_dir = scale(away, 1.0 / max(away_len, 1e-12)) if away_len > 1e-9 \
            else (0.0, 0.0, 1.0)
        goal = add_scaled(target, away_dir, cols.distance_m[i])
    held = False
    w = weight[i]
    if kind == codes.kind_area:
        goal = area_goal(cols, i, p0, target, was, codes)
        if not cols.area_inside[i] and cols.area_shape[i] == codes.area_sphere:
            held = norm(sub(goal, p0)) > 1e-9
            if cols.held[i] and not held:  # released: back toward the motion, at a speed
                back = sub(p0, was)
                gap = norm(back)
                goal = add_scaled(was, back, min(1.0, max_release_m / max(gap, 1e-12)))
                held = gap > max_release_m
        # An area the motion already keeps needs nothing: it must not claim its limb.
        if norm(sub(goal, p0)) < 1e-9:
            w = 0.0
    if kind == codes.kind_orientation:
        axis0 = to_world(segment_frame(dec, c, segment, t), load3(cols.axis[i]))
        look = cols.target_kind[i] != codes.target_world
        goal = normalize(sub(target, p0) if look else target)
        return normalize(to_world(rotation_toward(axis0, goal, math.pi, w), axis0)), w, held
    return add_scaled(p0, sub(goal, p0), w), w, held


@jit(nogil=True)
def goal_layout_rows(lo: int, hi: int, user_start: I64, idx: I64, cols: Columns, weight: F64,
                     targets: F64, dec: DecodedArrays, previous: DecodedArrays,
                     has_previous: bool, max_release_m: float, rows: I64, contact_weight: F64,
                     com_control: B8, com_desired: F64, t: Tables, codes: Codes,
                     out: GoalArrays, layout: bool) -> None:
    """The goals of the characters ``lo..hi-1`` (local rows; ``rows`` (r,) their store rows),
    laid out: character ``c``'s active constraints ``idx[user_start[c]:user_start[c + 1]]``
    (table rows, in the table's order) each one's goal (:func:`constraint_goal`; its weight 0
    where the motion already keeps an area: the caller drops those), then its two feet, each a
    goal of its leg to stay where ground adaptation put it (``dec.positions``, the pose before
    constraints), above every priority while in contact, below every one otherwise. Mirrors
    :func:`ecs_anim.solver.goals.tick_goals` where no goal is dropped (one pass over each
    character's constraints and pose, where computing the goals and laying them out took
    two). Without ``layout`` the columns that depend on the table and the active constraints
    alone (owner, table_index, orientation, group, bone, segment, fraction, offset, chain,
    axis: :class:`LayoutArrays`) are not written: ``out`` holds them from an earlier tick
    with the same active constraints (:class:`GoalLayouts`)."""
    for c in range(lo, hi):
        row = rows[c]
        for j in range(user_start[c], user_start[c + 1]):
            i = idx[j]
            goal, w, held = constraint_goal(i, cols, weight, targets, dec, previous,
                                            has_previous, max_release_m, t, codes)
            at = j + 2 * c
            if layout:
                out.owner[at] = c
                out.table_index[at] = i
                out.orientation[at] = cols.kind[i] == codes.kind_orientation
                out.group[at] = cols.group[i]
                out.bone[at] = cols.bone[i]
                out.segment[at] = cols.segment[i]
                out.fraction[at] = cols.fraction[i]
                store3(out.offset[at], load3(cols.offset[i]))
                out.chain[at] = cols.chain[i]
                store3(out.axis[at], load3(cols.axis[i]))
            out.priority[at] = cols.priority[i]
            store3(out.goal[at], goal)
            out.weight[at] = w
            out.held[at] = held
        for side in range(2):
            at = user_start[c + 1] + 2 * c + side
            ankle = load3(dec.positions[row, t.ankle[side]])
            in_contact = contact_weight[row, side] > 0
            if layout:
                out.owner[at] = c
                out.table_index[at] = -1
                out.orientation[at] = False
                out.group[at] = codes.leg_l + side
                out.bone[at] = 1
                out.segment[at] = t.shank[side]
                out.fraction[at] = 1.0
                store3(out.offset[at], (0.0, 0.0, 0.0))
                out.chain[at] = 1 << (codes.leg_l + side)
                store3(out.axis[at], (0.0, 0.0, 0.0))
            out.priority[at] = math.inf if in_contact else -math.inf
            store3(out.goal[at], ankle)
            out.weight[at] = 1.0
            out.held[at] = False
            store3(out.footprint[c, side], ankle)
            out.in_contact[c, side] = in_contact
        store3(out.com_desired[c], load3(com_desired[row]))
        out.com_on[c] = com_control[row]


@jit(nogil=True)
def target_rows(lo: int, hi: int, body: I64, owner: I64, target_row: I64, target_segment: I64,
                target_fraction: F64, target_offset: F64, dec: DecodedArrays,
                previous: DecodedArrays, has_previous: bool, t: Tables, out: F64) -> None:
    """``out[body[i]]`` ((m, 3), m) for ``i`` in ``lo..hi-1``: the target point of the
    constraint ``body[i]`` on a body, on ``dec`` (this tick's pose) when the body is its own,
    else on ``previous`` (the last tick's posture) where finite. Mirrors the body targets of
    :func:`ecs_anim.solver.goals.target_points`."""
    for i in range(lo, hi):
        j = body[i]
        row, segment = target_row[j], target_segment[j]
        offset = load3(target_offset[j])
        now = point_position(dec, row, segment, target_fraction[j], offset, t)
        if has_previous and row != owner[j]:
            now = finite_or(point_position(previous, row, segment, target_fraction[j], offset, t),
                            now)
        store3(out[j], now)


def target_points(table: ConstraintTable, unconstrained: DecodedPose,
                  previous: DecodedPose | None, wanted: NDArray[np.bool_] | None = None) -> F64:
    """Compiled :func:`ecs_anim.solver.goals.target_points`: the same arguments and result."""
    out = table.target_world.copy()
    on_body = table.target_kind != TARGET_WORLD
    body = np.flatnonzero(on_body if wanted is None else on_body & wanted)
    if body.size:
        dec = _arrays(unconstrained)
        over_chunks(target_rows, body.size, body, np.ascontiguousarray(table.owner),
                    np.ascontiguousarray(table.target_row),
                    np.ascontiguousarray(table.target_segment),
                    np.ascontiguousarray(table.target_fraction, dtype=np.float64),
                    np.ascontiguousarray(table.target_offset, dtype=np.float64), dec,
                    dec if previous is None else _arrays(previous), previous is not None,
                    TABLES, out, rows_per_thread=LIGHT_ROWS_PER_THREAD)
    return out


class CapsuleTables(NamedTuple):
    """:mod:`ecs_anim.solver.capsules`' tables the surface kernel reads (passed as an argument:
    numba's cache keeps another file's module constants as they were when compiled):
    ``joints`` (N_CAPSULES, 2), ``span`` (N_CAPSULES, 2), ``of_segment`` (N_LENGTHS,),
    ``radius_weights`` (N_CAPSULES, N_LENGTHS)."""

    joints: I64
    span: F64
    of_segment: I64
    radius_weights: F64


CAPSULE_TABLES = CapsuleTables(np.ascontiguousarray(CAPSULE_JOINTS, dtype=np.int64),
                               np.ascontiguousarray(CAPSULE_SPAN, dtype=np.float64),
                               np.ascontiguousarray(SEGMENT_CAPSULE, dtype=np.int64),
                               np.ascontiguousarray(RADIUS_WEIGHTS, dtype=np.float64))


@jit(inline="always")
def _nan_max(a: float, b: float) -> float:
    """``np.maximum(a, b)`` (NaN if ``a`` is)."""
    return a if (a != a or a > b) else b


@jit(inline="always")
def _radius(lengths: F64, row: int, capsule: int, caps: CapsuleTables) -> float:
    """:func:`ecs_anim.solver.capsules.capsule_radii` of character ``row``'s ``capsule``."""
    total = 0.0
    for k in range(lengths.shape[1]):
        total += lengths[row, k] * caps.radius_weights[capsule, k]
    return total


@jit(inline="always")
def _on_surface(target: Vec3, axis_a: Vec3, axis_b: Vec3, radius: float, effector: Vec3) -> Vec3:
    """Mirrors :func:`ecs_anim.solver.capsules.surface_points` for one target (NaN as there)."""
    ab = sub(axis_b, axis_a)
    t = dot(sub(target, axis_a), ab) / _nan_max(dot(ab, ab), 1e-18)
    if t < 0.0:
        t = 0.0
    elif t > 1.0:
        t = 1.0
    on_axis = add(axis_a, scale(ab, t))
    ab_len = norm(ab)
    along = (ab[0] / _nan_max(ab_len, 1e-12), ab[1] / _nan_max(ab_len, 1e-12),
             ab[2] / _nan_max(ab_len, 1e-12))
    way = sub(effector, on_axis)
    if t > 0.0 and t < 1.0:
        way = sub(way, scale(along, dot(way, along)))
    length = norm(way)
    if length > 1e-9:
        m = _nan_max(length, 1e-12)
        direction = (way[0] / m, way[1] / m, way[2] / m)
    else:  # the effector on the axis: any direction square to it
        other = (1.0, 0.0, 0.0) if abs(along[0]) < 0.9 else (0.0, 1.0, 0.0)
        square = sub(other, scale(along, dot(other, along)))
        m = _nan_max(norm(square), 1e-12)
        direction = (square[0] / m, square[1] / m, square[2] / m)
    return add(on_axis, scale(direction, radius))


@jit(nogil=True)
def surface_rows(lo: int, hi: int, other: I64, owner: I64, target_row: I64, target_segment: I64,
                 segment: I64, lengths: F64, now: F64, source: F64, previous: F64,
                 has_previous: bool, caps: CapsuleTables, t: Tables, out: F64) -> None:
    """``out[other[i]]`` ((m, 3), m) for ``i`` in ``lo..hi-1`` where the result is finite (else
    left): the position constraint ``other[i]``'s target (as ``out`` holds it) moved onto the
    surface of the capsule of another character's part it lies on. The capsule's axis from
    ``source`` (the posture of the last tick, this tick's without one), the way out toward the
    proximal joint of the constrained point's segment on ``previous`` where finite, else on
    ``now`` (all (n, N_JOINTS, 3) world m). Mirrors
    :func:`ecs_anim.solver.goals.on_other_surfaces`."""
    for i in range(lo, hi):
        j = other[i]
        row, own = target_row[j], owner[j]
        capsule = caps.of_segment[target_segment[j]]
        a = load3(source[row, caps.joints[capsule, 0]])
        b = load3(source[row, caps.joints[capsule, 1]])
        axis_a = add(a, scale(sub(b, a), caps.span[capsule, 0]))
        axis_b = add(a, scale(sub(b, a), caps.span[capsule, 1]))
        seg = segment[j]
        p, q = t.seg_proximal[seg], t.seg_distal[seg]
        base = plain_point(now, own, p, q, 0.0)
        was = base
        if has_previous:
            before = plain_point(previous, own, p, q, 0.0)
            was = finite_or(before, base)
        point_capsule = caps.of_segment[seg]
        radius = _radius(lengths, row, capsule, caps) + (
            _radius(lengths, own, point_capsule, caps) if point_capsule >= 0 else 0.0)
        moved = _on_surface(load3(out[j]), axis_a, axis_b, radius, was)
        if (math.isfinite(moved[0]) and math.isfinite(moved[1])
                and math.isfinite(moved[2])):
            store3(out[j], moved)


def on_other_surfaces(table: ConstraintTable, targets: F64, lengths: F64,
                      unconstrained: DecodedPose, previous: DecodedPose | None) -> F64:
    """Compiled :func:`ecs_anim.solver.goals.on_other_surfaces`: the same arguments and
    result."""
    other = other_surface_rows(table)
    if other.size == 0:
        return targets
    out = np.array(targets, dtype=np.float64, order="C")
    now = np.ascontiguousarray(unconstrained.positions, dtype=np.float64)
    before = now if previous is None else np.ascontiguousarray(previous.positions,
                                                               dtype=np.float64)
    over_chunks(surface_rows, other.size, other, np.ascontiguousarray(table.owner),
                np.ascontiguousarray(table.target_row), np.ascontiguousarray(table.target_segment),
                np.ascontiguousarray(table.segment),
                np.ascontiguousarray(lengths, dtype=np.float64), now, before, before,
                previous is not None, CAPSULE_TABLES, TABLES, out,
                rows_per_thread=LIGHT_ROWS_PER_THREAD)
    return out


def _arrays(decoded: DecodedPose) -> DecodedArrays:
    return DecodedArrays(*(np.ascontiguousarray(getattr(decoded, name), dtype=np.float64)
                           for name in DecodedArrays._fields))


class LayoutArrays(NamedTuple):
    """The goals' columns that depend on the table and on which of its constraints are active
    alone (with the feet's, which are always the same): :class:`GoalLayouts` keeps them. Same
    names and shapes as in :class:`GoalArrays`."""

    owner: I64
    table_index: I64
    orientation: B8
    group: I64
    bone: I64
    segment: I64
    fraction: F64
    offset: F64
    chain: I64
    axis: F64


#: The table's columns a layout is made of (those fields, the order, the goals aiming at a point
#: of their own body and where that point is).
LAYOUT_COLUMNS = ("owner", "kind", "group", "bone", "segment", "fraction", "offset", "chain",
                  "axis", "target_kind", "target_row", "target_segment", "target_fraction",
                  "target_offset")


class Layout(NamedTuple):
    """Where a tick's goals go: ``idx`` (a,) the active constraints by character, then in the
    table's order; ``rows`` (r,) their characters' store rows, ``user_start`` (r + 1,) each
    one's first in ``idx``; ``fields`` the :class:`LayoutArrays` ((k,) or (k, 3), k = a
    + 2 r; written by the first :func:`goal_layout_rows` on them); the goals aiming at a point
    of their own body: ``on_self`` (s,) their goal indices, ``self_idx`` (s,) their table rows,
    ``self_segment``, ``self_fraction``, ``self_offset`` that point."""

    idx: I64
    rows: I64
    user_start: I64
    fields: LayoutArrays
    on_self: I64
    self_idx: I64
    self_segment: I64
    self_fraction: F64
    self_offset: F64


def layout(table: ConstraintTable, active: B8) -> Layout | None:
    """The :class:`Layout` of the constraints ``active`` (m,) of ``table`` (None: none is)."""
    idx = np.flatnonzero(active)
    if idx.size == 0:
        return None
    idx = idx[np.argsort(table.owner[idx], kind="stable")]  # by character, then table order
    owner = table.owner[idx]
    first = np.ones(idx.size, np.bool_)  # the first goal of each character
    first[1:] = owner[1:] != owner[:-1]
    rows = owner[first]
    user_start = np.append(np.flatnonzero(first), idx.size)
    k = idx.size + 2 * rows.size
    fields = LayoutArrays(
        owner=np.empty(k, np.int64), table_index=np.empty(k, np.int64),
        orientation=np.empty(k, np.bool_), group=np.empty(k, np.int64),
        bone=np.empty(k, np.int64), segment=np.empty(k, np.int64), fraction=np.empty(k),
        offset=np.empty((k, 3)), chain=np.empty(k, np.int64), axis=np.empty((k, 3)))
    # each user goal's place: its index in idx, after two feet per character before it
    user_at = np.arange(idx.size) + 2 * np.cumsum(first) - 2
    on_self = _aiming_at_own_body(table, idx)
    self_idx = idx[on_self]
    return Layout(idx, rows, user_start, fields, user_at[on_self], self_idx,
                  table.target_segment[self_idx], table.target_fraction[self_idx],
                  table.target_offset[self_idx])


def _aiming_at_own_body(table: ConstraintTable, idx: I64) -> I64:
    """The positions in ``idx`` (table rows) of the constraints whose target is a point of their
    own character's body (usually none: no target is on a body)."""
    on_body = table.target_kind[idx] != TARGET_WORLD
    if not on_body.any():
        return np.zeros(0, np.int64)
    return np.flatnonzero(on_body & (table.target_row[idx] == table.owner[idx]))


def goals_on_layout(kept: Layout, written: bool, table: ConstraintTable, weight: F64, targets: F64,
                    unconstrained: DecodedPose, contact_weight: F64,
                    com_control: NDArray[np.bool_], com_desired: F64,
                    previous: DecodedPose | None, max_release_m: float) -> TickGoals | None:
    """:func:`tick_goals` (the arguments from ``table`` on are its) on the layout ``kept`` of
    the constraints active in ``weight``; ``written``: its :class:`LayoutArrays` hold this
    table's already (not written again). The goals share those arrays with every other tick's
    goals on the same layout: nothing writes them (the solve moves ``goal`` alone)."""
    idx, rows, user_start = kept.idx, kept.rows, kept.user_start
    r = rows.size
    k = idx.size + 2 * r
    out = GoalArrays(**kept.fields._asdict(), priority=np.empty(k), goal=np.empty((k, 3)),
                     weight=np.empty(k), held=np.empty(k, np.bool_), footprint=np.empty((r, 2, 3)),
                     in_contact=np.empty((r, 2), np.bool_), com_desired=np.empty((r, 3)),
                     com_on=np.empty(r, np.bool_))
    dec = _arrays(unconstrained)
    over_chunks(goal_layout_rows, r, user_start, idx, columns(table),
                np.ascontiguousarray(weight, dtype=np.float64),
                np.ascontiguousarray(targets, dtype=np.float64), dec,
                dec if previous is None else _arrays(previous), previous is not None,
                float(max_release_m), rows, np.ascontiguousarray(contact_weight, dtype=np.float64),
                np.ascontiguousarray(com_control, dtype=np.bool_),
                np.ascontiguousarray(com_desired, dtype=np.float64), TABLES, CODES, out,
                not written)
    on_self, self_idx = kept.on_self, kept.self_idx
    self_segment, self_fraction, self_offset = (kept.self_segment, kept.self_fraction,
                                                kept.self_offset)
    if not (out.weight > 0).all():  # areas the motion already keeps (rare): not goals
        user = out.table_index >= 0
        kept_goals = out.weight[user] > 0
        if not kept_goals.any():
            return None
        out, rows = _without_dropped(out, rows, user, kept_goals)
        idx = idx[kept_goals]
        at_self = _aiming_at_own_body(table, idx)
        on_self, self_idx = np.flatnonzero(out.table_index >= 0)[at_self], idx[at_self]
        self_segment, self_fraction, self_offset = (table.target_segment[self_idx],
                                                    table.target_fraction[self_idx],
                                                    table.target_offset[self_idx])
    return TickGoals(
        rows=rows, **out._asdict(), on_self=on_self, self_segment=self_segment,
        self_fraction=self_fraction, self_offset=self_offset,
        self_start=np.take(targets, self_idx, axis=0))  # (a row gather 4 x as fast as [])


def tick_goals(table: ConstraintTable, weight: F64, targets: F64, unconstrained: DecodedPose,
               contact_weight: F64, com_control: NDArray[np.bool_], com_desired: F64,
               previous: DecodedPose | None = None,
               max_release_m: float = np.inf) -> TickGoals | None:
    """Compiled :func:`ecs_anim.solver.goals.tick_goals`: the same arguments and result."""
    kept = layout(table, weight > 0)
    if kept is None:
        return None
    return goals_on_layout(kept, False, table, weight, targets, unconstrained, contact_weight,
                           com_control, com_desired, previous, max_release_m)


#: An array's type, shape and bytes: equal for arrays the same to the bit.
Contents = tuple[np.dtype[np.generic], tuple[int, ...], bytes]


def _contents(column: NDArray[np.generic]) -> Contents:
    """``column``'s :data:`Contents`. Bytes compare faster than ``np.array_equal`` (a
    comparison array, then its reduction: 6.5 us a column at a few rows, against 0.1; the
    14 columns of 8,000 constraints out of cache 0.22 ms against 0.17)."""
    return column.dtype, column.shape, column.tobytes()


class GoalLayouts:
    """:func:`tick_goals` from tick to tick (ConstraintSolve's): the :class:`Layout` is kept
    while the same constraints are active and the table's :data:`LAYOUT_COLUMNS` are the same
    (compared with copies kept, every tick: the table may be changed in place), so the sort of
    the active constraints and the :class:`LayoutArrays` columns (about 1.7 MB at 4,000
    characters with two constraints each) are not made again; the same goals, bit for bit."""

    def __init__(self) -> None:
        self._kept: Layout | None = None
        self._active = _contents(np.zeros(0, np.bool_))
        self._columns: tuple[Contents, ...] = ()

    def _same(self, table: ConstraintTable, active: B8) -> bool:
        """Whether the kept layout is that of ``active`` (m,) in ``table`` (its columns the
        same to the bit: a 0.0 that became -0.0 is a change)."""
        return (self._kept is not None and _contents(active) == self._active
                and all(_contents(getattr(table, name)) == column
                        for name, column in zip(LAYOUT_COLUMNS, self._columns, strict=True)))

    def __call__(self, table: ConstraintTable, weight: F64, targets: F64,
                 unconstrained: DecodedPose, contact_weight: F64,
                 com_control: NDArray[np.bool_], com_desired: F64,
                 previous: DecodedPose | None = None,
                 max_release_m: float = np.inf) -> TickGoals | None:
        active = weight > 0
        written = self._same(table, active)
        if not written:
            self._kept = None  # (kept again once its fields are written)
            kept = layout(table, active)
            if kept is None:
                return None
        else:
            assert self._kept is not None
            kept = self._kept
        goals = goals_on_layout(kept, written, table, weight, targets, unconstrained,
                                contact_weight, com_control, com_desired, previous, max_release_m)
        if not written:
            self._kept, self._active = kept, _contents(active)
            self._columns = tuple(_contents(getattr(table, name)) for name in LAYOUT_COLUMNS)
        return goals


def _without_dropped(out: GoalArrays, rows: I64, user: B8, kept: B8) -> tuple[GoalArrays, I64]:
    """``out`` and ``rows`` without the goals not ``kept`` (of the ``user`` goals, (k,)), nor the
    characters left with none (their feet and rows go with them; the others' local rows
    renumbered)."""
    keep_user = np.zeros(user.size, np.bool_)
    keep_user[np.flatnonzero(user)[kept]] = True
    has = np.zeros(rows.size, np.bool_)
    has[out.owner[keep_user]] = True
    keep = np.where(user, keep_user, has[out.owner])
    local = np.cumsum(has) - 1
    per_row = ("footprint", "in_contact", "com_desired", "com_on")
    arrays = {name: value[has] if name in per_row else value[keep]
              for name, value in out._asdict().items()}
    arrays["owner"] = local[arrays["owner"]]
    return GoalArrays(**arrays), rows[has]


class OwnTargets(NamedTuple):
    """The table's columns of a target on a body (same names; (m,) or (m, 3)), and whether
    :func:`error_rows` reads the targets on their own character's body again on the pose it
    measures (``again``)."""

    target_row: I64
    target_segment: I64
    target_fraction: F64
    target_offset: F64
    again: bool


def own_targets(table: ConstraintTable, again: bool) -> OwnTargets:
    """The table's body-target columns as :func:`error_rows` takes them."""
    return OwnTargets(np.ascontiguousarray(table.target_row),
                      np.ascontiguousarray(table.target_segment),
                      np.ascontiguousarray(table.target_fraction, dtype=np.float64),
                      np.ascontiguousarray(table.target_offset, dtype=np.float64), again)


@jit(nogil=True)
def error_rows(lo: int, hi: int, idx: I64, cols: Columns, dec: DecodedArrays, targets: F64,
               own: OwnTargets, t: Tables, codes: Codes, out: F64) -> None:
    """``out[j]`` (a,): how far constraint ``idx[j]`` is from being met on ``dec``, for
    ``j`` in ``lo..hi-1``; with ``own.again`` a target on the constraint's own character's
    body read on ``dec`` (as :func:`target_rows` does), not from ``targets``. Mirrors
    :func:`ecs_anim.solver.goals.constraint_errors` (with ``again``,
    :func:`ecs_anim.solver.goals.errors_on_result`)."""
    for j in range(lo, hi):
        i = idx[j]
        c = cols.owner[i]
        segment = cols.segment[i]
        point = point_position(dec, c, segment, cols.fraction[i], load3(cols.offset[i]), t)
        target = load3(targets[i])
        if own.again and cols.target_kind[i] != codes.target_world and own.target_row[i] == c:
            target = point_position(dec, c, own.target_segment[i], own.target_fraction[i],
                                    load3(own.target_offset[i]), t)
        kind = cols.kind[i]
        if kind == codes.kind_area:
            out[j] = norm(sub(point, area_goal(cols, i, point, target, point, codes)))
        elif kind == codes.kind_orientation:
            axis = to_world(segment_frame(dec, c, segment, t), load3(cols.axis[i]))
            look = cols.target_kind[i] != codes.target_world
            direction = normalize(sub(target, point) if look else target)
            out[j] = math.acos(min(max(dot(axis, direction), -1.0), 1.0))
        else:
            gap = norm(sub(point, target))
            out[j] = abs(gap - cols.distance_m[i]) if kind == codes.kind_distance else gap


def _errors(table: ConstraintTable, idx: I64, decoded: DecodedPose, targets: F64,
            again: bool) -> F64:
    idx = np.ascontiguousarray(idx, dtype=np.int64)
    out = np.empty(idx.size)
    over_chunks(error_rows, idx.size, idx, columns(table), _arrays(decoded),
                np.ascontiguousarray(targets, dtype=np.float64), own_targets(table, again),
                TABLES, CODES, out, rows_per_thread=LIGHT_ROWS_PER_THREAD)
    return out


def constraint_errors(table: ConstraintTable, idx: I64, decoded: DecodedPose, targets: F64) -> F64:
    """Compiled :func:`ecs_anim.solver.goals.constraint_errors`: the same arguments and
    result."""
    return _errors(table, idx, decoded, targets, False)


def errors_on_result(table: ConstraintTable, idx: I64, decoded: DecodedPose, targets: F64) -> F64:
    """Compiled :func:`ecs_anim.solver.goals.errors_on_result`: the same arguments and result
    (the targets on the own body read in the errors' loop, not in a pass of their own)."""
    return _errors(table, idx, decoded, targets, True)


assert CONTACT_PRIORITY == math.inf  # the layout writes a planted foot's priority as inf
