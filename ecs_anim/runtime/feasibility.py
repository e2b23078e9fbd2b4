"""Can each constraint's body reach its target at all? A feasibility pass (issue 32, item 6).

Before a run, and when a body or a target changes, each constraint gets one estimate: the
longest its chain can stretch (its *reach*: the bones from the chain's anchor to the
constrained point, the spine's length too when the trunk is in the chain) against the
distance from that anchor to the target's surface, in the poses the character and its
target's character may take (:func:`pose_library`). A constraint whose nearest approach is
still beyond its reach *cannot reach* its target, by so much; the others *can*, with so much to
spare. The estimate errs on the side of reach (the chain stretched straight, the nearest of the
poses): a constraint said short is short, one said within reach may still be kept off by
higher priorities or joint limits.

Where the bodies stand: each character's poses are its clips decoded on its body, laid out
from its placement (a clip it does not play now as if it started now, continuing its root path,
as :func:`~ecs_anim.runtime.playback_queue.start_clips` does), on the ground it stands on
(``store.ground_ref``): the stance's root height and the ground are in the anchor's height.
A constraint active in a clip's own time is looked at in that clip over its activation; any
other in every pose of the character's clips. Its target's character is looked at in every
pose of the clips it may play: the one it plays, those queued, its locomotion set's, and those
a trigger's ``Play`` gives it. Targets on another character's body part are on that part's
surface (the capsule's, out by the constrained point's own radius, as the solver aims:
:func:`ecs_anim.solver.goals.on_other_surfaces`).

Estimated: ``position`` and ``distance`` constraints, ``area`` constraints that keep a point
*inside* a sphere or a box. Not a question of reach (left out, ``checked`` False): orientations,
areas to stay out of, half-spaces, and targets not finite (a target your code has not set).

Batched over constraints and poses (numpy); a Python loop only over the joints of a chain
(at most six). Not part of the tick: :meth:`Simulation.feasibility` runs it when asked.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.body_points import (
    ABOVE_TRUNK,
    GROUPS,
    JOINT_AS_POINT,
    SEG_DISTAL,
    SEG_PROXIMAL,
    SEGMENTS,
    TRUNK,
    point_positions,
)
from ecs_anim.core.ground import sheerest
from ecs_anim.core.ground_adapt import STEP_UP_PER_LEG
from ecs_anim.core.morphology import Morphology, leg_length
from ecs_anim.core.normalized import DecodedPose, decode
from ecs_anim.core.skeleton import BONE_JOINTS, JOINT_INDEX, JOINTS, LENGTHS, N_JOINTS, PARENTS
from ecs_anim.motion.constraint_table import (
    AREA_BOX,
    AREA_SPHERE,
    KIND_AREA,
    KIND_DISTANCE,
    KIND_POSITION,
    TARGET_WORLD,
    ConstraintTable,
)
from ecs_anim.motion.sampling import rotate_xy, sample, sample_table, wrap_angle
from ecs_anim.runtime.triggers import Play
from ecs_anim.solver.capsules import (
    CAPSULE_JOINTS,
    CAPSULE_SPAN,
    SEGMENT_CAPSULE,
    capsule_radii,
    point_radii,
    surface_points,
)

if TYPE_CHECKING:
    from ecs_anim.runtime.simulation import Simulation

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: Poses looked at per clip (evenly over the clip, or over a constraint's activation in it).
POSES_PER_CLIP = 9
#: A constraint is said to fall short when its target is beyond its reach by more than this
#: (m): the estimate's own slack (the centre-of-mass control and ground adaptation move the
#: root by a few centimetres either way).
SHORT_TOLERANCE_M = 0.02

#: The joint each length's bone ends at, and back: the bone (length index) ending at a joint.
_BONE_ENDING_AT = np.full(N_JOINTS, -1, np.int64)
for _index, (_a, _b) in enumerate(BONE_JOINTS):
    if _b >= 0:
        _BONE_ENDING_AT[_b] = _index
_PARENT = np.array(PARENTS, np.int64)
#: The joint a group's chain hangs from when the trunk does not move for it.
_GROUP_ANCHOR = np.array([JOINT_INDEX[j] for j in ("hip_l", "hip_r", "neck", "shoulder_l",
                                                    "shoulder_r", "pelvis")], np.int64)
_PELVIS = JOINT_INDEX["pelvis"]
#: The solver group of each length's points (-1: the root's, which takes no constraint).
_SEGMENT_GROUP = np.array([SEGMENTS[n][0] if n in SEGMENTS else -1 for n in LENGTHS], np.int64)
#: Constraints estimated in one pass (each pass holds (own poses x target poses) pairs of each).
CONSTRAINTS_PER_PASS = 256


@dataclass(frozen=True)
class Feasibility:
    """One constraint's estimate (:func:`feasibility`).

    uid, character, constraint : the constraint's id, its character's name, its name.
    target : what it aims at, as a line says it (``defender_4's spine_upper``, ``(x, y, z)``).
    chain : the groups allowed to move for it that bring its point nearer (``leg_r``,
        ``arm_l+trunk``; not the trunk for a target on the body that the trunk carries).
    stature_m : its character's stature (m).
    reach_m : the longest its chain stretches, anchor to point (m).
    short_m : by how much its target stays beyond that reach at the nearest (m; negative: to
        spare; NaN when not checked).
    checked : whether reach is the question (False: an orientation, a keep-out area, a
        half-space, a target not finite).
    reachable : not checked, or short by at most :data:`SHORT_TOLERANCE_M`.
    """

    uid: int
    character: str
    constraint: str
    target: str
    chain: str
    stature_m: float
    reach_m: float
    short_m: float
    checked: bool

    @property
    def reachable(self) -> bool:
        return not self.checked or self.short_m <= SHORT_TOLERANCE_M

    @property
    def line(self) -> str:
        """The estimate in one line: ``kick of kicker_4 (1.20 m, leg_r 0.56 m) cannot reach
        defender_4's spine_upper: 0.31 m short``."""
        who = f"{self.constraint} of {self.character} ({self.stature_m:.2f} m, {self.chain} "
        if not self.checked:
            return f"{who}{self.reach_m:.2f} m): {self.target}: not a question of reach"
        if self.reachable:
            spare = max(-self.short_m, 0.0)
            return f"{who}{self.reach_m:.2f} m) can reach {self.target}: {spare:.2f} m to spare"
        return f"{who}{self.reach_m:.2f} m) cannot reach {self.target}: {self.short_m:.2f} m short"

    def as_dict(self) -> dict[str, object]:
        """As the run report's JSON has it (``feasibility``)."""
        return {"character": self.character, "constraint": self.constraint,
                "target": self.target, "chain": self.chain,
                "stature_m": round(self.stature_m, 4), "reach_m": round(self.reach_m, 4),
                "short_m": None if not self.checked else round(self.short_m, 4),
                "checked": self.checked, "reachable": self.reachable, "line": self.line}


def feasibility_lines(estimates: list[Feasibility]) -> list[str]:
    """What ``run`` prints before the first tick: ``feasibility: <line>`` for each constraint
    that cannot reach its target, then how many can (none when there is no constraint)."""
    checked = [e for e in estimates if e.checked]
    lines = [f"feasibility: {e.line}" for e in checked if not e.reachable]
    if estimates:
        within = sum(e.reachable for e in checked)
        rest = len(estimates) - len(checked)
        lines.append(f"feasibility: {within} of {len(checked)} constraints can reach their "
                     f"targets" + (f"; {rest} are not a question of reach" if rest else ""))
    return lines


#: The steepest grade a foot can stand on (rise over run: 45 degrees).
MAX_GRADE = 1.0


def ground_lines(sim: Simulation) -> list[str]:
    """What ``run`` prints before the first tick about the ground (one line each, none when
    every body can walk it): a rise taller than the shortest-legged character can step up
    (:data:`STEP_UP_PER_LEG` of its leg), a grade steeper than a foot can stand on
    (:data:`MAX_GRADE`). A character walking into such a rise stops at it (GroundAdapt); a
    grade is walked onto."""
    step_m, grade = sheerest(sim.ground)
    lines = []
    legs = sim.leg_length()
    if legs.size and step_m > STEP_UP_PER_LEG * legs.min():
        who = sim.names()[int(np.argmin(legs))]
        lines.append(f"ground: a rise of {step_m:.2f} m, more than {who} can step up "
                     f"({STEP_UP_PER_LEG * legs.min():.2f} m, half its leg): a character walking "
                     "into it stops there")
    if grade > MAX_GRADE:
        lines.append(f"ground: a grade of {np.degrees(np.arctan(grade)):.0f} degrees, steeper "
                     f"than a foot can stand on ({np.degrees(np.arctan(MAX_GRADE)):.0f}): a "
                     "character walking onto it is not stopped")
    return lines


def chain_reach(lengths: F64, segment: I64, fraction: F64, offset: F64,
                chain: I64) -> tuple[F64, I64]:
    """How far each constrained point can be from its chain's anchor, the chain stretched
    straight (m (k,)), and that anchor joint (k,).

    ``lengths`` (k, N_LENGTHS) each constraint's body; ``segment`` (k,) length index of the
    point, ``fraction`` (k,) along it, ``offset`` (k, 3) m in its frame; ``chain`` (k,) bit
    mask of :data:`~ecs_anim.core.body_points.GROUPS`. The anchor is the group's root joint
    (hip, shoulder, neck base), or the pelvis when the trunk moves for a point above it."""
    group = _SEGMENT_GROUP[segment]
    with_trunk = ((chain >> TRUNK) & 1).astype(bool) & np.isin(group, ABOVE_TRUNK)
    anchor = np.where(with_trunk | (group == TRUNK), _PELVIS, _GROUP_ANCHOR[group])
    k = np.arange(segment.size)
    reach = fraction * lengths[k, segment] + np.linalg.norm(offset, axis=1)
    joint = SEG_PROXIMAL[segment]
    # Up the skeleton from the point's segment to the anchor (a chain is at most six bones).
    for _ in range(N_JOINTS):
        climbing = joint != anchor
        if not climbing.any():
            break
        bone = _BONE_ENDING_AT[np.where(climbing, joint, anchor)]
        reach = reach + np.where(climbing & (bone >= 0), lengths[k, np.maximum(bone, 0)], 0.0)
        joint = np.where(climbing, _PARENT[joint], joint)
    return reach, anchor


def _point_name(segment: int, fraction: float) -> str:
    """A target point as a scenario names it: the joint a segment ends at (fraction 1), else
    the segment."""
    joint = int(SEG_DISTAL[segment])
    if fraction == 1.0 and joint >= 0 and JOINTS[joint] in JOINT_AS_POINT:
        return JOINTS[joint]
    return LENGTHS[segment]


def _chain_text(mask: int) -> str:
    return "+".join(g for i, g in enumerate(GROUPS) if mask >> i & 1) or "none"


def playable_clips(sim: Simulation, rows: I64 | None = None) -> list[list[int]]:
    """Per store row (or per one of ``rows`` (k,), in that order), the clips the character may
    play (bank indices): the one it plays, those queued, its locomotion set's, and those a
    trigger's ``Play`` (and its ``then``) gives it."""
    st, bank = sim.store, sim.bank
    picked = list(range(st.n)) if rows is None else [int(r) for r in rows]
    at = {r: i for i, r in enumerate(picked)}
    row_of = {int(e): r for r, e in enumerate(st.entity.tolist())}
    clips: list[list[int]] = [[int(st.clip[r])] for r in picked]
    for i, r in enumerate(picked):
        clips[i] += st.queue_clip[r, :st.queue_len[r]].tolist() + \
            [int(c) for c in st.gait_clip[r] if c >= 0]
    for trigger in sim.reactions.triggers:
        for action in trigger.then:
            if isinstance(action, Play) and row_of.get(action.entity, -1) in at:
                names = [action.clip] + [q.clip for q in action.then]
                clips[at[row_of[action.entity]]] += [bank.index(n) for n in names]
    return [list(dict.fromkeys(c)) for c in clips]


def pose_library(sim: Simulation, lengths: F64, rows: I64, clips: I64,
                 times_s: F64) -> DecodedPose:
    """Poses (q,) of characters ``rows`` (q,) playing ``clips`` (q,) at ``times_s`` (q,) of
    each clip, decoded on their bodies ``lengths`` (n, N_LENGTHS) by store row: the clip a character plays now laid out from its
    placement; another as if started now, its root continuing the one now played (with its
    heading, as :func:`~ecs_anim.runtime.playback_queue.start_clips`); feet on the ground the
    character stands on (its ``ground_ref``)."""
    st, bank = sim.store, sim.bank
    leg = leg_length(lengths[rows])
    now = sample(bank, st.clip[rows], st.clip_time_s[rows], st.loop[rows])
    begun = sample(bank, clips, np.zeros(rows.size), np.zeros(rows.size, bool))
    heading = st.placement_heading[rows]
    root_now = rotate_xy(now.root_position[:, :2] * leg[:, None], heading) + st.placement_xy[rows]
    playing = clips == st.clip[rows]
    new_heading = wrap_angle(now.root_heading + heading - begun.root_heading)
    new_xy = root_now - rotate_xy(begun.root_position[:, :2] * leg[:, None], new_heading)
    heading = np.where(playing, heading, new_heading)
    xy = np.where(playing[:, None], st.placement_xy[rows], new_xy)
    loop = np.where(playing, st.loop[rows], False)
    poses = sample(bank, clips, times_s, loop)
    root = poses.root_position.copy()
    root[:, :2] = (rotate_xy(root[:, :2] * leg[:, None], heading) + xy) / leg[:, None]
    root[:, 2] += (st.ground_ref[rows] / leg
                   - sample_table(bank, bank.capture_ground, clips, times_s, loop)[:, 0])
    poses.root_position = root
    poses.root_heading = poses.root_heading + heading
    return decode(poses, lengths[rows])


def _even(start: F64, stop: F64) -> F64:
    """(k, POSES_PER_CLIP) times evenly from ``start`` to ``stop`` (k,)."""
    u = np.linspace(0.0, 1.0, POSES_PER_CLIP)
    times: F64 = start[:, None] + u[None] * (stop - start)[:, None]
    return times


def body_lengths(sim: Simulation) -> F64:
    """(n, N_LENGTHS) each character's body as the estimate takes it: its Morphology
    component's (while a blend runs, the body it blends into)."""
    lengths = sim.store.lengths.copy()
    body_rows, bodies = sim.rows_and_components(Morphology)
    lengths[body_rows] = [b.lengths for b in bodies]
    return lengths


def feasibility(sim: Simulation, constraints: I64 | None = None) -> list[Feasibility]:
    """Every constraint's estimate (the module docstring), in the constraint table's order, on
    the bodies the characters have or are blending into (their Morphology components); or those
    of the table rows ``constraints`` (k,) alone, in that order: the same estimates (each
    constraint's own poses and its target's, nothing shared), made from those characters'
    poses only."""
    table, st, bank = sim.constraints, sim.store, sim.bank
    if table.m == 0 or st.n == 0:
        return []
    ks = np.arange(table.m) if constraints is None else np.asarray(constraints, np.int64)
    m = ks.size
    if m == 0:
        return []
    lengths = body_lengths(sim)
    names = sim.names()
    duration = bank.duration_s(np.arange(bank.n_frames.size))
    owner = table.owner[ks]
    body = table.target_kind[ks] != TARGET_WORLD
    target_row = np.where(body, table.target_row[ks], owner)
    # The library of every character these constraints involve: each playable clip at
    # POSES_PER_CLIP times over it (as wide as the one that plays the most; the rest padded,
    # left out of every minimum).
    involved = np.unique(np.concatenate([owner, target_row]))
    playable = playable_clips(sim, involved)
    width = max(len(c) for c in playable) * POSES_PER_CLIP
    lib_clip = np.full((st.n, width), -1, np.int64)
    for r, clips in zip(involved.tolist(), playable, strict=True):
        lib_clip[r, :len(clips) * POSES_PER_CLIP] = np.repeat(clips, POSES_PER_CLIP)
    in_library = lib_clip >= 0
    lib_clip = np.where(in_library, lib_clip, st.clip[:, None])
    phase = np.tile(np.linspace(0.0, 1.0, POSES_PER_CLIP), width // POSES_PER_CLIP)
    lib_time = phase[None] * duration[lib_clip]

    # The constraint's own poses: its clock's clip over its activation, or the whole library.
    clocked = table.clock[ks] >= 0
    clock = np.maximum(table.clock[ks], 0)
    start = np.clip(table.activation[ks, 0], 0.0, duration[clock])
    stop = np.clip(table.activation[ks, 1], start, duration[clock])
    own_clip = np.where(clocked[:, None], np.pad(np.repeat(clock[:, None], POSES_PER_CLIP, 1),
                                                 ((0, 0), (0, width - POSES_PER_CLIP)), "edge"),
                        lib_clip[owner])
    own_time = np.where(clocked[:, None],
                        np.pad(_even(start, stop), ((0, 0), (0, width - POSES_PER_CLIP)), "edge"),
                        lib_time[owner])
    own_ok = np.where(clocked[:, None], True, in_library[owner])
    own = pose_library(sim, lengths, np.repeat(owner, width), own_clip.reshape(-1), own_time.reshape(-1))

    # A target on the body itself that the trunk carries moves with the trunk: the trunk
    # brings the point no nearer to it.
    self_target = body & (target_row == owner)
    carried = self_target & np.isin(_SEGMENT_GROUP[table.target_segment[ks]], ABOVE_TRUNK)
    chain = np.where(carried, table.chain[ks] & ~(1 << TRUNK), table.chain[ks])
    reach, anchor_joint = chain_reach(lengths[owner], table.segment[ks], table.fraction[ks],
                                      table.offset[ks], chain)
    anchor = own.positions[np.arange(m * width), np.repeat(anchor_joint, width)].reshape(m, width, 3)

    # Targets: (m, width) points (a world target repeated); the library of the characters
    # another's target lies on (``lib_row``: each constraint's target's block in it).
    targeted = np.unique(target_row[body & ~self_target])
    lib = pose_library(sim, lengths, np.repeat(targeted, width), lib_clip[targeted].reshape(-1),
                       lib_time[targeted].reshape(-1)) if targeted.size else None
    lib_row = np.zeros(st.n, np.int64)
    lib_row[targeted] = np.arange(targeted.size)
    lib_row = lib_row[target_row]
    segment = np.repeat(table.target_segment[ks], width)
    fraction = np.repeat(table.target_fraction[ks], width)
    offset = np.repeat(table.target_offset[ks], width, axis=0)
    target_points = np.repeat(table.target_world[ks], width, axis=0)
    on_other = np.flatnonzero(np.repeat(body & ~self_target, width))
    if on_other.size:
        assert lib is not None
        pose = (lib_row[:, None] * width + np.arange(width)[None]).reshape(-1)[on_other]
        target_points[on_other] = point_positions(lib, pose, segment[on_other],
                                                  fraction[on_other], offset[on_other])
    on_self = np.flatnonzero(np.repeat(self_target, width))
    if on_self.size:
        target_points[on_self] = point_positions(own, on_self, segment[on_self],
                                                 fraction[on_self], offset[on_self])
    target_points = target_points.reshape(m, width, 3)
    target_ok = np.where(self_target[:, None], own_ok, in_library[target_row]) | ~body[:, None]

    # Distances from every own pose's anchor to every target pose (self targets: same pose),
    # a pass of constraints at a time.
    nearest = np.empty(m)
    for first in range(0, m, CONSTRAINTS_PER_PASS):
        some = np.arange(first, min(first + CONSTRAINTS_PER_PASS, m))
        gap = _needed(lengths, table, ks[some], target_row[some], lib_row[some],
                      target_points[some], anchor[some], lib, width)
        pair_ok = own_ok[some, :, None] & target_ok[some, None, :]
        pair_ok &= np.where(self_target[some, None, None], np.eye(width, dtype=bool)[None], True)
        nearest[some] = np.min(np.where(pair_ok, gap, np.inf), axis=(1, 2))
    kind = table.kind[ks]
    checked = np.isfinite(nearest) & (
        (kind == KIND_POSITION) | (kind == KIND_DISTANCE)
        | ((kind == KIND_AREA) & table.area_inside[ks]
           & np.isin(table.area_shape[ks], (AREA_SPHERE, AREA_BOX))))
    short = np.where(checked, nearest - reach, np.nan)
    stature = [Morphology(lengths[r]).stature for r in owner]
    out = []
    for i, k in enumerate(ks.tolist()):
        r = int(owner[i])
        if body[i]:
            point = _point_name(int(table.target_segment[k]), float(table.target_fraction[k]))
            whose = "its own" if self_target[i] else f"{names[int(target_row[i])]}'s"
            target = f"{whose} {point}"
        else:
            x, y, z = table.target_world[k]
            target = f"({x:.2f}, {y:.2f}, {z:.2f})"
        out.append(Feasibility(int(table.uid[k]), names[r], table.names[k], target,
                               _chain_text(int(chain[i])), float(stature[i]),
                               float(reach[i]), float(short[i]), bool(checked[i])))
    return out


def _needed(lengths: F64, table: ConstraintTable, ks: I64, target_row: I64, lib_row: I64,
            target_points: F64, anchor: F64, lib: DecodedPose | None, width: int) -> F64:
    """(k, width, width) how far each constraint ``ks`` (k,) (rows of ``table``) must take its
    point from its anchor (own pose, target pose): to the target's surface (a position on
    another character's capsule), to the target less the distance kept (distance), to the
    area (inside areas), else to the target. ``target_row`` (k,), ``target_points`` (k, width,
    3) and ``anchor`` (k, width, 3) are theirs; ``lib`` the characters' poses, ``width`` each."""
    a = anchor[:, :, None, :]  # (k, own, 1, 3)
    t = target_points[:, None, :, :]  # (k, 1, target, 3)
    straight = np.linalg.norm(t - a, axis=-1)
    needed = straight.copy()
    owner, kind, shape_of_area = table.owner[ks], table.kind[ks], table.area_shape[ks]
    # Onto another character's body part: its capsule's surface, toward the anchor.
    capsule = SEGMENT_CAPSULE[table.target_segment[ks]]
    on_surface = ((table.target_kind[ks] != TARGET_WORLD) & (target_row != owner)
                  & (kind == KIND_POSITION) & (capsule >= 0))
    s = np.flatnonzero(on_surface)
    if s.size:
        assert lib is not None
        joints = CAPSULE_JOINTS[capsule[s]]
        pose = lib_row[s][:, None] * width + np.arange(width)[None]  # (s, width)
        ends_a = lib.positions[pose, joints[:, None, 0]]
        ends_b = lib.positions[pose, joints[:, None, 1]]
        span = CAPSULE_SPAN[capsule[s]][:, None]
        axis_a = ends_a + span[..., :1] * (ends_b - ends_a)
        axis_b = ends_a + span[..., 1:] * (ends_b - ends_a)
        radius = (capsule_radii(lengths[target_row[s]])[np.arange(s.size), capsule[s]]
                  + point_radii(lengths[owner[s]], table.segment[ks[s]]))
        shape = (s.size, width, width)

        def pairs(v: F64, own_axis: bool) -> F64:
            """(s, width, 3) -> (s * width * width, 3) over (own, target) pairs."""
            spread = v[:, :, None] if own_axis else v[:, None, :]
            return np.broadcast_to(spread, shape + (3,)).reshape(-1, 3)

        surface = surface_points(pairs(target_points[s], False), pairs(axis_a, False),
                                 pairs(axis_b, False),
                                 np.repeat(radius, width * width), pairs(anchor[s], True))
        needed[s] = np.linalg.norm(surface - pairs(anchor[s], True), axis=-1).reshape(shape)
    distance = kind == KIND_DISTANCE
    needed = np.where(distance[:, None, None], straight - table.distance_m[ks, None, None], needed)
    sphere = (kind == KIND_AREA) & (shape_of_area == AREA_SPHERE)
    needed = np.where(sphere[:, None, None], straight - table.area_radius[ks, None, None], needed)
    box = (kind == KIND_AREA) & (shape_of_area == AREA_BOX)
    if box.any():
        rel = a - t  # the anchor from the box's placement point
        low, high = table.area_low[ks, None, None, :], table.area_high[ks, None, None, :]
        outside = np.linalg.norm(rel - np.clip(rel, low, high), axis=-1)
        needed = np.where(box[:, None, None], outside, needed)
    out: F64 = np.maximum(needed, 0.0)
    return out


__all__ = ["POSES_PER_CLIP", "SHORT_TOLERANCE_M", "Feasibility", "body_lengths", "chain_reach",
           "feasibility", "feasibility_lines", "playable_clips", "pose_library"]
