"""The goals of a tick (paper §9): what the constraint solver's shell (:mod:`.shell`) iterates on.

Per tick, :func:`tick_goals` turns the active constraints into fixed goals: each constraint's
point as the motion has it (``P0``), its full goal (``G``: the target, the point at a distance
from it, its projection into an area, a direction) and the goal blended by the activation
weight (``P0 + w (G - P0)``: the ramp blends from the motion, so iterating never compounds it).
Each foot becomes a goal of its leg (stay where ground adaptation put it, facing the same way):
above every priority while in contact, below every priority while free. Goals aiming at a point
of the same body follow that point as the body is solved. :func:`constraint_errors` measures how
far each constraint is from being met.

The compiled :func:`ecs_anim.runtime.kernels.goals.tick_goals` mirrors this numpy reference.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.body_points import LEG_L, point_positions, segment_frames
from ecs_anim.core.normalized import SIDE_JOINTS, DecodedPose
from ecs_anim.core.rotations import normalize
from ecs_anim.core.skeleton import LENGTH_INDEX as L
from ecs_anim.motion.constraint_table import (
    AREA_BOX,
    AREA_HALF_SPACE,
    AREA_SPHERE,
    KIND_AREA,
    KIND_DISTANCE,
    KIND_ORIENTATION,
    KIND_POSITION,
    TARGET_WORLD,
    ConstraintTable,
)
from ecs_anim.solver.capsules import (
    CAPSULE_JOINTS,
    CAPSULE_SPAN,
    SEGMENT_CAPSULE,
    capsule_radii,
    point_radii,
    surface_points,
)
from ecs_anim.solver.steps import rotation_toward

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: A foot's goal while in contact: above every constraint's priority.
CONTACT_PRIORITY = np.inf
#: The shank of each leg [l, r], the segment a foot goal's point is placed on.
SHANK = (L["shank_l"], L["shank_r"])


@dataclass
class TickGoals:
    """The k goals of this tick for the r characters being solved (local rows 0..r-1).

    Sorted by character (owner), each character's goals in the table's order, its two feet
    last. rows (r,) store rows; owner (k,) local row; table_index (k,) (-1: a foot contact);
    orientation (k,) bool; group, bone, segment, fraction, offset (k, 3), chain (bit mask),
    priority; goal (k, 3): the weighted point goal, or the weighted unit direction of an
    orientation; weight (k,); axis (k, 3) segment-frame axis of an orientation; footprint (r, 2, 3)
    and in_contact (r, 2): the feet that must stay; com_desired (r, 3); com_on (r,) bool.
    """

    rows: I64
    owner: I64
    table_index: I64
    orientation: NDArray[np.bool_]
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
    footprint: F64
    in_contact: NDArray[np.bool_]
    com_desired: F64
    com_on: NDArray[np.bool_]
    on_self: I64  # (s,) goals aiming at a point of their own body: they follow it in the solve
    self_segment: I64
    self_fraction: F64
    self_offset: F64
    self_start: F64  # (s, 3) where that point was when the goals were made
    held: NDArray[np.bool_]  # (k,) a sphere keeps this goal's point off the motion's place
    # The frame budget's cut (None: the settings' iterations for every goal and character):
    # (k,) the iterations after which a goal no longer keeps its character's loop going nor
    # turns the trunk, (r,) the most iterations each character gets.
    goal_iterations: I64 | None = None
    row_iterations: I64 | None = None

    @property
    def k(self) -> int:
        return int(self.owner.shape[0])


def target_points(table: ConstraintTable, unconstrained: DecodedPose, previous: DecodedPose | None,
                  wanted: NDArray[np.bool_] | None = None) -> F64:
    """(m, 3) every constraint's target point this tick: world points as given; a point on the
    constrained character itself from its pose before constraints (this tick); a point on
    another character from that character's posture of the previous tick (this tick's
    unconstrained pose on the first tick). ``wanted`` (m,): only those points on a body are
    computed (the others' rows are ``target_world``'s: the frame budget solves a few of many
    characters)."""
    out = table.target_world.copy()
    on_body = table.target_kind != TARGET_WORLD
    body = np.flatnonzero(on_body if wanted is None else on_body & wanted)
    if body.size:
        rows = table.target_row[body]
        seg, frac, off = table.target_segment[body], table.target_fraction[body], table.target_offset[body]
        now = point_positions(unconstrained, rows, seg, frac, off)
        other = np.flatnonzero(rows != table.owner[body])
        if previous is not None and other.size:
            before = point_positions(previous, rows[other], seg[other], frac[other], off[other])
            # A character added since the last tick has no posture there yet: its pose now.
            now[other] = np.where(np.isfinite(before), before, now[other])
        out[body] = now
    return out


def other_surface_rows(table: ConstraintTable) -> I64:
    """The position constraints of ``table`` whose target is a point of *another* character's
    body part that has a capsule (:func:`on_other_surfaces` moves their targets)."""
    on_other = (table.target_kind != TARGET_WORLD) & (table.target_row != table.owner)
    if not on_other.any():  # (usually none: no gather of the segments' capsules)
        return np.zeros(0, np.int64)
    out: I64 = np.flatnonzero(on_other & (table.kind == KIND_POSITION)
                              & (SEGMENT_CAPSULE[table.target_segment] >= 0))
    return out


def on_other_surfaces(table: ConstraintTable, targets: F64, lengths: F64,
                      unconstrained: DecodedPose, previous: DecodedPose | None) -> F64:
    """``targets`` (m, 3) with every position constraint's target on *another* character's
    body part moved onto that part's surface (DESIGN §8b): from the nearest point of the part's
    capsule axis (:mod:`ecs_anim.solver.capsules`) to the target, out by the capsule's radius
    and the constrained point's own (its segment's capsule), toward where the proximal joint of
    the constrained point's segment was last tick (:func:`~ecs_anim.solver.capsules.
    surface_points`: the segment then leaves the surface outward). A kick at the chest lands
    on it, not in it; the errors, measured against these targets, are then to the surface.
    The capsule is read from the other character's posture of the last tick (as the target
    point: :func:`target_points`). Targets on a part without a capsule, on the constrained
    character itself, in the world, and other kinds are left. A new array when any moves."""
    other = other_surface_rows(table)
    if other.size == 0:
        return targets
    rows, owner = table.target_row[other], table.owner[other]
    capsule = SEGMENT_CAPSULE[table.target_segment[other]]
    source = unconstrained.positions if previous is None else previous.positions
    joints = CAPSULE_JOINTS[capsule]
    a, b = source[rows, joints[:, 0]], source[rows, joints[:, 1]]
    span = CAPSULE_SPAN[capsule]
    axis_a, axis_b = a + span[:, :1] * (b - a), a + span[:, 1:] * (b - a)
    # Out toward where the point's segment comes from (its proximal joint, last tick): the
    # segment then leaves the surface outward (a kick's shank does not cross the chest).
    seg = table.segment[other]
    base, zero = np.zeros(other.size), np.zeros((other.size, 3))
    now = point_positions(unconstrained, owner, seg, base, zero)
    was = now if previous is None else point_positions(previous, owner, seg, base, zero)
    was = np.where(np.isfinite(was), was, now)
    radius = (capsule_radii(lengths[rows])[np.arange(other.size), capsule]
              + point_radii(lengths[owner], table.segment[other]))
    moved = surface_points(targets[other], axis_a, axis_b, radius, was)
    ok = np.isfinite(moved).all(axis=1)  # no capsule yet (a character just added): the point
    out = targets.copy()
    out[other[ok]] = moved[ok]
    return out


def _area_goal(table: ConstraintTable, idx: I64, point: F64, anchor: F64,
               side: F64 | None = None) -> F64:
    """Nearest point of each constraint's allowed region (inside or outside its area) to
    ``point`` (k, 3); the area sits at ``anchor`` (k, 3). A point inside an area it must leave
    goes out on the side of ``side`` (k, 3; default the point itself): through the box face,
    or along the sphere's radius, nearest to it."""
    shape, inside = table.area_shape[idx], table.area_inside[idx]
    rel = point - anchor
    rel_side = rel if side is None else side - anchor
    low, high = table.area_low[idx], table.area_high[idx]
    # Box: clamp inside; outside, push through the face nearest the side point.
    in_box = np.clip(rel, low, high)
    gaps = np.concatenate([rel_side - low, high - rel_side], axis=1)  # (k, 6) to each face
    face = np.argmin(gaps, axis=1)
    out_box = rel.copy()
    axis = face % 3
    k = np.arange(idx.size)
    out_box[k, axis] = np.where(face < 3, low[k, axis], high[k, axis])
    strictly_inside = np.all((rel > low) & (rel < high), axis=1)
    box = np.where(inside[:, None], in_box, np.where(strictly_inside[:, None], out_box, rel))
    # Sphere about the anchor.
    distance = np.linalg.norm(rel, axis=1)
    radius = table.area_radius[idx]
    # A sphere to stay out of is left on the side point's side, and its far side is not reached
    # through it: while the way from the side point to the point crosses the sphere, the goal
    # stays on the surface facing the side point (a head behind a fist stays behind it).
    way = rel - rel_side
    along = np.clip(-np.sum(rel_side * way, axis=1) / np.maximum(np.sum(way * way, axis=1), 1e-18), 0.0, 1.0)
    nearest_on_way = np.linalg.norm(rel_side + along[:, None] * way, axis=1)
    leave = ~inside & ((distance < radius) | (nearest_on_way < radius))
    side_len = np.linalg.norm(rel_side, axis=1)
    toward = np.where((leave & (side_len > 1e-12))[:, None], rel_side, rel)
    toward_len = np.linalg.norm(toward, axis=1)
    direction = np.where((toward_len > 1e-12)[:, None], toward / np.maximum(toward_len, 1e-12)[:, None],
                         [0.0, 0.0, 1.0])
    sphere = direction * np.where(inside, np.minimum(distance, radius),
                                  np.where(leave, radius, distance))[:, None]
    # Half-space: the allowed side is where the normal points (the other side when outside).
    normal = table.area_normal[idx] * np.where(inside, 1.0, -1.0)[:, None]
    height = np.sum(rel * normal, axis=1)
    half = rel - np.minimum(height, 0.0)[:, None] * normal
    goal = np.select([(shape == AREA_BOX)[:, None], (shape == AREA_SPHERE)[:, None],
                      (shape == AREA_HALF_SPACE)[:, None]], [box, sphere, half], rel)
    allowed: F64 = anchor + goal
    return allowed


def constraint_errors(table: ConstraintTable, idx: I64, decoded: DecodedPose, targets: F64) -> F64:
    """(k,) how far each constraint ``idx`` (k,) is from being met on ``decoded`` (every
    character's pose), against this tick's ``targets`` (m, 3): position, the distance to the
    target; distance, how far from ``distance_m`` of it; area, the distance to the allowed
    region (0 anywhere in it); metres. Orientation: the angle (radians) from its direction.
    The solver aims at one goal point per constraint, fixed for the tick; this is the measure a
    user means (a point anywhere outside a sphere it must leave has met it)."""
    owner = table.owner[idx]
    seg, frac, off = table.segment[idx], table.fraction[idx], table.offset[idx]
    point = point_positions(decoded, owner, seg, frac, off)
    t = targets[idx]
    kind = table.kind[idx]
    gap = np.linalg.norm(point - t, axis=1)
    err: F64 = np.where(kind == KIND_DISTANCE, np.abs(gap - table.distance_m[idx]), gap)
    area = kind == KIND_AREA
    if area.any():
        allowed = _area_goal(table, idx[area], point[area], t[area])
        err[area] = np.linalg.norm(point[area] - allowed, axis=1)
    orient = kind == KIND_ORIENTATION
    if orient.any():
        o = np.flatnonzero(orient)
        axis = np.einsum("kij,kj->ki", segment_frames(decoded, owner[o], seg[o]), table.axis[idx[o]])
        look = table.target_kind[idx[o]] != TARGET_WORLD
        direction = normalize(np.where(look[:, None], t[o] - point[o], t[o]))
        err[o] = np.arccos(np.clip(np.sum(axis * direction, axis=1), -1.0, 1.0))
    return err


def errors_on_result(table: ConstraintTable, idx: I64, decoded: DecodedPose, targets: F64) -> F64:
    """:func:`constraint_errors` of the constraints ``idx`` on a solve's result ``decoded``, the
    targets on their own character's body read again on it (they moved with the body as it was
    solved); the others' ``targets`` (m, 3) as they were."""
    on_body = table.target_kind != TARGET_WORLD
    on_own_body = on_body & (table.target_row == table.owner) if on_body.any() else on_body
    if on_own_body.any():
        wanted = np.zeros(table.m, bool)
        wanted[idx] = True
        targets = np.where(on_own_body[:, None],
                           target_points(table, decoded, None, on_own_body & wanted), targets)
    return constraint_errors(table, idx, decoded, targets)


def tick_goals(table: ConstraintTable, weight: F64, targets: F64, unconstrained: DecodedPose,
               contact_weight: F64, com_control: NDArray[np.bool_], com_desired: F64,
               previous: DecodedPose | None = None, max_release_m: float = np.inf) -> TickGoals | None:
    """This tick's goals from the table, its weights (m,) and target points (m, 3) (all finite
    where the weight is > 0), for the characters with an active constraint; None if there is
    none. ``unconstrained`` is this tick's decoded pose of every character before constraints;
    ``contact_weight`` (n, 2); ``com_control`` (n,); ``com_desired`` (n, 3); ``previous`` the
    last tick's posture (None on the first tick).

    A distance goal, and an area the point must leave, keep the point on the side of its target
    where it was last tick: a head dodging a fist that has come past where the motion holds the
    head goes on backwards instead of through the fist to its front. A point such a sphere held
    off the motion's place last tick (``table.held``) and no longer holds goes back at most
    ``max_release_m`` this tick."""
    idx = np.flatnonzero(weight > 0)
    if idx.size == 0:
        return None
    idx = idx[np.argsort(table.owner[idx], kind="stable")]  # by character, then table order
    owner = table.owner[idx]
    seg, frac, off = table.segment[idx], table.fraction[idx], table.offset[idx]
    p0 = point_positions(unconstrained, owner, seg, frac, off)
    was = p0 if previous is None else point_positions(previous, owner, seg, frac, off)
    # No last tick for this point (a character added since, a frozen pose): the motion's side.
    was = np.where(np.isfinite(was), was, p0)
    kind = table.kind[idx]
    t = targets[idx]
    away = was - t
    away_len = np.linalg.norm(away, axis=1, keepdims=True)
    away_dir = np.where(away_len > 1e-9, away / np.maximum(away_len, 1e-12), [0.0, 0.0, 1.0])
    goal = np.where((kind == KIND_DISTANCE)[:, None], t + table.distance_m[idx, None] * away_dir, t)
    is_area = kind == KIND_AREA
    if is_area.any():
        goal[is_area] = _area_goal(table, idx[is_area], p0[is_area], t[is_area], was[is_area])
    sphere_out = is_area & ~table.area_inside[idx] & (table.area_shape[idx] == AREA_SPHERE)
    held = sphere_out & (np.linalg.norm(goal - p0, axis=1) > 1e-9)
    released = sphere_out & table.held[idx] & ~held
    if released.any():
        back = p0[released] - was[released]
        gap = np.linalg.norm(back, axis=1)
        share = np.minimum(1.0, max_release_m / np.maximum(gap, 1e-12))
        goal[released] = was[released] + share[:, None] * back
        held[released] = gap > max_release_m
    w = weight[idx]
    # An area the motion already keeps (and a sphere it need not cross to get there) needs
    # nothing: it must not claim its limb.
    w = np.where(is_area & (np.linalg.norm(goal - p0, axis=1) < 1e-9), 0.0, w)
    orient = kind == KIND_ORIENTATION
    if orient.any():
        frames = segment_frames(unconstrained, owner[orient], seg[orient])
        axis0 = np.einsum("kij,kj->ki", frames, table.axis[idx[orient]])
        look = table.target_kind[idx[orient]] != TARGET_WORLD
        direction = normalize(np.where(look[:, None], t[orient] - p0[orient], t[orient]))
        goal[orient] = direction
    weighted = p0 + w[:, None] * (goal - p0)
    if orient.any():
        weighted[orient] = normalize(np.einsum(
            "kij,kj->ki", rotation_toward(axis0, goal[orient], weight=w[orient]), axis0))
    keep = w > 0
    if not keep.any():
        return None
    idx, owner, w = idx[keep], owner[keep], w[keep]
    rows, local = np.unique(owner, return_inverse=True)
    r, n_user = rows.size, idx.size
    # Each character's goals, then its two feet: where each user goal and each foot goes.
    user_end = np.cumsum(np.bincount(local, minlength=r))
    at_user = np.arange(n_user) + 2 * local
    at_foot = (user_end + 2 * np.arange(r))[:, None] + np.arange(2)  # (r, 2)
    at_foot = at_foot.reshape(-1)
    k = n_user + 2 * r

    def place(user: np.ndarray, foot: np.ndarray | float | int) -> np.ndarray:
        out = np.empty((k, *user.shape[1:]), dtype=user.dtype)
        out[at_user] = user
        out[at_foot] = foot
        return out

    on_self = np.flatnonzero((table.target_kind[idx] != TARGET_WORLD) & (table.target_row[idx] == owner))
    # Each foot keeps where ground adaptation put it: above every goal while in contact; below
    # every goal otherwise (a free foot stays clear of the ground when the root moves, unless a
    # constraint of that leg takes it).
    ankles = unconstrained.positions[rows][:, list(SIDE_JOINTS["ankle"])]
    in_contact = contact_weight[rows] > 0
    sides = np.tile(np.arange(2), r)
    foot_priority = np.where(in_contact.reshape(-1), CONTACT_PRIORITY, -CONTACT_PRIORITY)
    return TickGoals(
        rows=rows,
        owner=place(local, np.repeat(np.arange(r), 2)),
        table_index=place(idx, -1),
        orientation=place(orient[keep], False),
        group=place(table.group[idx], LEG_L + sides),
        bone=place(table.bone[idx], 1),
        segment=place(seg[keep], np.asarray(SHANK)[sides]),
        fraction=place(frac[keep], 1.0),
        offset=place(off[keep], 0.0),
        chain=place(table.chain[idx], 1 << (LEG_L + sides)),
        priority=place(table.priority[idx], foot_priority),
        goal=place(weighted[keep], ankles.reshape(-1, 3)),
        weight=place(w, 1.0),
        axis=place(table.axis[idx], 0.0),
        footprint=ankles,
        in_contact=in_contact,
        com_desired=com_desired[rows],
        com_on=com_control[rows],
        on_self=at_user[on_self],
        self_segment=table.target_segment[idx[on_self]],
        self_fraction=table.target_fraction[idx[on_self]],
        self_offset=table.target_offset[idx[on_self]],
        self_start=targets[idx[on_self]],
        held=place(held[keep], False),
    )
