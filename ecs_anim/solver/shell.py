"""The constraint solver's shell (paper §9): priorities, iterations, tolerance, budget.

The goals of a tick come from :func:`~ecs_anim.solver.goals.tick_goals`.
:func:`solve` then iterates, as the paper does, over the body's groups in the order legs, head,
arms, trunk, then the root (``adaptRoot``: centre-of-mass control). Each iteration starts with a
pass over legs, head and arms (the analytic steps, which leave the feet on their footprints and
the limbs on their goals after the last root move); a character stops at the pass after which
no iteration would change anything (no goal that the trunk turns for, or that follows its own
body, left within reach of improving, and its centre of mass so close that the root would not
move), or when the iteration budget is spent: that pass is its result (so its result does not
depend on who else is solved).
Inside a group, the highest-priority goal is met analytically (limbs; neck and head as a
two-segment chain) or by CCD rotations (trunk, about the spine's base, spread along the spine
spline); a limb's second goal swivels the limb about the axis that keeps the first one. The trunk
serves the highest-priority goal it can still improve, and a trunk move that would worsen a
higher-priority goal is not made. The steps are pure functions over all characters at once
(:mod:`ecs_anim.solver.steps`); this module owns the policy (:func:`constrain`: one tick of it,
and :func:`scatter`, the solved rows written back). The solver works on the characters with an
active constraint only.

This numpy :func:`solve` is the reference: the tick runs the compiled
:func:`ecs_anim.runtime.kernels.solve.solve` (same arguments, same results to 1e-9 m), which the
tests compare with it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.body_points import (
    ABOVE_TRUNK,
    HEAD,
    SEGMENTS,
    TRUNK,
    point_positions,
    segment_frames,
)
from ecs_anim.core.errors import UsageError
from ecs_anim.core.ground_adapt import MAX_LEG_EXTENSION, vertical_slack_for_reach
from ecs_anim.core.morphology import MASS_SEGMENTS, centres_of_mass, leg_length
from ecs_anim.core.normalized import (
    SIDE_JOINTS,
    SIDE_LENGTHS,
    DecodedPose,
    NormalizedPoses,
    decode,
    distal_frames,
    two_bone_middle,
)
from ecs_anim.core.rotations import (
    axis_angle,
    frame_from_axes,
    matrix_from_quat,
    normalize,
    quat_from_matrix,
)
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import LENGTH_INDEX as L
from ecs_anim.core.skeleton import LENGTHS
from ecs_anim.motion.constraint_table import ConstraintTable, winners
from ecs_anim.solver.budget import BudgetCut, SolverCostModel, cut_to_budget
from ecs_anim.solver.goals import (
    TickGoals,
    constraint_errors,
    errors_on_result,
    on_other_surfaces,
    target_points,
    tick_goals,
)
from ecs_anim.solver.steps import (
    bring_within_reach,
    middle_after_root_move,
    point_in_limb,
    reach_point,
    rotation_toward,
    turn_about_axis,
)

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: The default bound on how much faster than the motion a joint may move because of the solver
#: (m/s, ``SolverSettings.max_joint_speed_m_s``): a deliberate reach's speed. Captured people
#: raising a hand move the wrist at about 2.7 m/s (played on an adult at 30 Hz; the hand 3.8),
#: where a punch or a kick reach 5-11 m/s at the wrist or ankle (docs/api.md, No pops, names the
#: captures). A correction up to this speed (the 1 s ease of a 0.85 m reach peaks
#: at 2.4 m/s) is not touched; what goes faster was a pop.
MAX_JOINT_SPEED_M_S = 3.0


@dataclass(frozen=True)
class SolverSettings:
    """The shell's policy. ``iterations``: budget per tick; ``tolerance_m`` / ``tolerance_rad``:
    a goal closer than this is met; ``com_tolerance_m``: the same for the horizontal centre of
    mass; ``max_ccd_step_rad``: the largest turn one CCD step of the
    trunk makes (spreads a lean over the iterations); ``root_gain``: how far past the
    centre-of-mass error the root steps where its step is not predicted (a planted leg would
    leave its reach; a goal keeps the character iterating anyway, or aims at the world or at
    another character; elsewhere the step is the one that puts the centre of mass back once the
    planted feet re-plant: ``_Solve.root_move``);
    ``release_speed_m_s``: how fast a point a sphere held off the motion's place goes back to it
    once the sphere lets it go (instead of in one tick); ``stall_fraction``: a goal has stalled
    when its error no longer changes by the tolerance, or when it falls by less than this share
    of itself in two iterations running (0 turns the second test off): an unreachable goal
    creeping closer by a trunk step at a time no longer keeps the loop, and every character in
    it, going.

    The frame budget (:mod:`ecs_anim.solver.budget`): ``budget_ms`` the most a whole tick may
    take, ms (None: no budget); when the tick would overrun it, the lowest priorities, then the
    characters furthest from ``focus_in_world`` (a world point, m; None: the earlier rows are
    cut first), get fewer iterations. ``cost_model``: the cost the cut is decided by (None:
    calibrated every tick from the last tick's measured times).

    ``max_joint_speed_m_s``: how much faster than the motion's own a joint may move because of
    the solver, m/s: each joint's correction (how far the solve puts it from the motion's, from
    the pelvis) changes by at most this much a second (:data:`MAX_JOINT_SPEED_M_S` by default,
    a person's deliberate reach; None: as fast as the solve likes). A trunk the solve folds in
    one tick then bends over several, a constraint switched on at once is met over a few ticks
    (:mod:`ecs_anim.solver.joint_speed`)."""

    iterations: int = 6
    tolerance_m: float = 1e-4
    tolerance_rad: float = 1e-3
    com_tolerance_m: float = 1e-3
    max_ccd_step_rad: float = np.radians(20.0)
    root_gain: float = 1.25
    release_speed_m_s: float = 1.5
    stall_fraction: float = 0.05
    budget_ms: float | None = None
    focus_in_world: tuple[float, float, float] | None = None
    cost_model: SolverCostModel | None = None
    max_joint_speed_m_s: float | None = MAX_JOINT_SPEED_M_S

    def __post_init__(self) -> None:
        if self.max_joint_speed_m_s is not None and not (
                np.isfinite(self.max_joint_speed_m_s) and self.max_joint_speed_m_s > 0):
            raise UsageError(f"max_joint_speed_m_s must be a positive number of metres a "
                             f"second or None, got {self.max_joint_speed_m_s}")
        if not 0.0 <= self.stall_fraction < 1.0:
            raise UsageError(f"stall_fraction must be in [0, 1), got {self.stall_fraction}")
        if self.budget_ms is not None and not (np.isfinite(self.budget_ms) and self.budget_ms > 0):
            raise UsageError(f"budget_ms must be a positive number of milliseconds or None, "
                             f"got {self.budget_ms}")
        if self.focus_in_world is not None and not (
                len(self.focus_in_world) == 3 and np.all(np.isfinite(self.focus_in_world))):
            raise UsageError(f"focus_in_world must be a finite (x, y, z) point or None, "
                             f"got {self.focus_in_world}")


DEFAULT_SETTINGS = SolverSettings()

#: A target with a coordinate beyond this (m, 1,000 km) is a mistake, not a place: its squares
#: lose the solver's precision (and overflow beyond 1e154 m, giving a non-finite pose), so its
#: constraint is switched off as a non-finite one is.
MAX_TARGET_M = 1e6
# The four limbs [leg_l, leg_r, arm_l, arm_r]: their group, joints (root, middle, end, distal
# end), lengths (upper, lower, distal) and how far they may stretch.
LIMB_OF_GROUP = np.array([0, 1, -1, 2, 3, -1])
LIMB_J = tuple(np.array([J[f"{leg}_l"], J[f"{leg}_r"], J[f"{arm}_l"], J[f"{arm}_r"]])
               for leg, arm in (("hip", "shoulder"), ("knee", "elbow"), ("ankle", "wrist"),
                                ("toe", "hand")))
LIMB_LENGTHS = tuple(np.array([L[f"{leg}_l"], L[f"{leg}_r"], L[f"{arm}_l"], L[f"{arm}_r"]])
                     for leg, arm in (("thigh", "upper_arm"), ("shank", "forearm"), ("foot", "hand")))
LIMB_EXTENSION = np.array([MAX_LEG_EXTENSION, MAX_LEG_EXTENSION, 1.0, 1.0])
#: Per limb (4, 3): the mass segments (:data:`ecs_anim.core.morphology.MASS_SEGMENTS`) of its
#: upper, lower and distal bones.
LIMB_MASS = np.array([[[segment[0] for segment in MASS_SEGMENTS].index(f"{bone}_{side}")
                       for bone in bones]
                      for bones in (("thigh", "shank", "foot"), ("upper_arm", "forearm", "hand"))
                      for side in ("l", "r")])
#: The root step's probe (m): how far along x and y it moves the root in its prediction to
#: measure how the centre of mass follows (its Jacobian).
ROOT_PROBE_M = 1e-3
#: The least determinant of that Jacobian for which the step is predicted (the body moves
#: the centre of mass by about 0.6-1 times the root's move; below this it is no prediction).
MIN_ROOT_JACOBIAN = 0.1
# Per group [leg_l, leg_r, head, arm_l, arm_r, trunk]: the root and middle joint of the limb the
# trunk carries (-1: not carried), and the share of its length the trunk aims to bring a goal
# within (a little bent, so the limb's own step then meets it).
LIMB_ROOT_JOINT = np.array([-1, -1, J["neck"], J["shoulder_l"], J["shoulder_r"], -1])
LIMB_MIDDLE_JOINT = np.array([-1, -1, J["head"], J["elbow_l"], J["elbow_r"], -1])
LIMB_REACH_SHARE = 0.99
#: Per segment (N_LENGTHS,): whether a pass of the solve (limbs, head) moves it. A goal whose
#: target follows such a point of its own body is met by the pass's limb only as the point
#: stood before the pass moved it: it needs iterations. A target on the trunk or the pelvis
#: moves only with the trunk and the root, and each pass follows it before meeting it.
SEGMENT_MOVED_BY_PASS = np.array([name in SEGMENTS and SEGMENTS[name][0] != TRUNK
                                  for name in LENGTHS])


def iteration_caps(goals: TickGoals, settings: SolverSettings) -> tuple[I64, I64]:
    """(k,) the iterations each goal may keep its character's loop going, and (r,) the most
    iterations each character gets: the frame budget's cut, or the settings' ``iterations``."""
    full = int(settings.iterations)
    goal_caps = (np.full(goals.k, full, np.int64) if goals.goal_iterations is None
                 else goals.goal_iterations)
    row_caps = (np.full(goals.rows.size, full, np.int64) if goals.row_iterations is None
                else goals.row_iterations)
    return goal_caps, row_caps


def _errors(g: TickGoals, dec: DecodedPose) -> F64:
    """(k,) distance of each point to its (weighted) goal of this tick (m), or the angle of each
    orientation (rad): the solver's convergence measure (users see :func:`constraint_errors`)."""
    point = point_positions(dec, g.owner, g.segment, g.fraction, g.offset)
    goal = g.goal
    err: F64 = np.linalg.norm(point - goal, axis=1)
    if g.orientation.any():
        o = np.flatnonzero(g.orientation)
        axis = np.einsum("kij,kj->ki", segment_frames(dec, g.owner[o], g.segment[o]), g.axis[o])
        err[o] = np.arccos(np.clip(np.sum(axis * goal[o], axis=1), -1.0, 1.0))
    return err


class _Solve:
    """One tick's solve over r characters: the poses being changed and their decoded form,
    kept in step by each group's update (a full decode happens once per iteration)."""

    def __init__(self, poses: NormalizedPoses, lengths: F64, goals: TickGoals,
                 masses: F64, com_fraction: F64, settings: SolverSettings,
                 decoded: DecodedPose | None) -> None:
        self.poses = NormalizedPoses(**{k: v.copy() for k, v in poses.arrays().items()})
        self.lengths, self.g, self.s = lengths, goals, settings
        self.masses, self.com_fraction = masses, com_fraction
        self.r = int(goals.rows.size)
        if decoded is None:
            self.dec = decode(self.poses, lengths)
        else:
            self.dec = DecodedPose(**{k: getattr(decoded, k).copy() for k in (
                "positions", "pelvis2world", "thorax2world", "head2world", "leg2world", "arm2world")})
        g = goals
        self.is_point = ~g.orientation
        # Winners never change within a tick: computed once. Limbs by (row, limb), the head by row.
        limb = LIMB_OF_GROUP[g.group]
        on_limb = limb >= 0
        self.first_limb = winners(g.owner, limb, g.priority, on_limb & self.is_point, self.r, 4)
        taken = np.zeros(g.k, bool)
        taken[self.first_limb[self.first_limb >= 0]] = True
        self.second_limb = winners(g.owner, limb, g.priority, on_limb & self.is_point & ~taken, self.r, 4)
        self.orient_limb = winners(g.owner, limb, g.priority, on_limb & g.orientation, self.r, 4)
        zero = np.zeros(g.k, np.int64)
        on_head = g.group == HEAD
        self.first_head = winners(g.owner, zero, g.priority, on_head & self.is_point, self.r, 1)[:, 0]
        self.orient_head = winners(g.owner, zero, g.priority, on_head & g.orientation, self.r, 1)[:, 0]
        # The goals a limb or the head meets first (analytically, on every pass).
        self.is_first = np.zeros(g.k, bool)
        self.is_first[self.first_limb[self.first_limb >= 0]] = True
        self.is_first[self.first_head[self.first_head >= 0]] = True
        self.self_at = goals.self_start.copy()
        self.follows_body = np.zeros(g.k, bool)  # (k,) the goals following a point of the body
        self.follows_body[g.on_self] = True
        # (r,) the characters whose root step is predicted (:meth:`root_move`): those without
        # a goal that keeps iterating (the trunk's, or one following what a pass moves) and
        # whose every user goal follows their own body (set by :func:`solve`)
        self.predicted = np.ones(self.r, bool)
        p = self.dec.positions
        self.foot_in_world = normalize(p[:, list(SIDE_JOINTS["toe"])] - p[:, list(SIDE_JOINTS["ankle"])])
        # The characters still being solved: each stops when its own goals are met or stalled
        # and its centre of mass is back (so its result does not depend on who else is solved).
        self.active = np.ones(self.r, bool)
        # Goals that stopped improving (unreachable): the trunk no longer turns for them, so an
        # unreachable trunk goal ends where it stalled however long other goals keep the loop
        # going (turning on, the bent spine would drift it by millimetres).
        self.stalled = np.zeros(goals.k, bool)

    def follow_own_targets(self) -> None:
        """Goals aiming at a point of the same body move with that point as the body is solved
        (the root and trunk move both hands when one holds the other)."""
        g = self.g
        if g.on_self.size == 0:
            return
        now = point_positions(self.dec, g.owner[g.on_self], g.self_segment, g.self_fraction, g.self_offset)
        shift = now - self.self_at
        self.self_at = now
        orient = g.orientation[g.on_self]
        g.goal[g.on_self[~orient]] += shift[~orient]

    def _decode(self, rows: I64) -> None:
        """Decode ``rows`` (local) again from their poses (after a trunk turn: a bent spine's
        joints are exact once decoded); the others keep their decoded pose as their steps left
        it."""
        fresh = decode(self.poses.take(rows), self.lengths[rows])
        for name in ("positions", "pelvis2world", "thorax2world", "head2world", "leg2world",
                     "arm2world"):
            getattr(self.dec, name)[rows] = getattr(fresh, name)

    # --- limbs: analytic, all four at once (legs and arms do not move each other) ----------
    def limbs(self) -> None:
        """Each limb's highest-priority goal met analytically, its second by swivelling about
        the axis that keeps the first; then the foot / hand orientation goal."""
        dec, poses, g = self.dec, self.poses, self.g
        frames = np.concatenate([dec.leg2world, dec.arm2world], axis=1)  # (r, 4, 3, 3)
        fractions = np.concatenate([poses.leg_fraction, poses.arm_fraction], axis=1)
        dirs = np.concatenate([poses.foot_dir, poses.hand_dir], axis=1)
        rows, li = np.nonzero((self.first_limb >= 0) & self.active[:, None])
        # Only limbs with something to do: a first goal not met, or a second one not met (the
        # swivel for it keeps the first exactly; a limb left alone keeps both as they are: an
        # arm the root carried with both its goals, on the body, is not solved again).
        c = self.first_limb[rows, li]
        met = np.linalg.norm(point_positions(dec, rows, g.segment[c], g.fraction[c], g.offset[c])
                             - g.goal[c], axis=1) <= self.s.tolerance_m * 0.01
        second = self.second_limb[rows, li]
        two = np.flatnonzero(met & (second >= 0))
        if two.size:
            c2 = second[two]
            met[two] = np.linalg.norm(
                point_positions(dec, rows[two], g.segment[c2], g.fraction[c2], g.offset[c2])
                - g.goal[c2], axis=1) <= self.s.tolerance_m * 0.01
        todo = ~met
        rows, li = rows[todo], li[todo]
        if rows.size:
            c = self.first_limb[rows, li]
            u, ll, h = (self.lengths[rows, LIMB_LENGTHS[k][li]] for k in range(3))
            root = dec.positions[rows, LIMB_J[0][li]]
            q, on_lower = _bone_coords(g.bone[c], g.fraction[c], g.offset[c], u, ll, h, dirs[rows, li])
            frame, new_fraction, point = reach_point(root, frames[rows, li], u, ll, fractions[rows, li],
                                                     on_lower, q, g.goal[c], LIMB_EXTENSION[li])
            two = np.flatnonzero(self.second_limb[rows, li] >= 0)
            if two.size:
                c2 = self.second_limb[rows[two], li[two]]
                q2, lower2 = _bone_coords(g.bone[c2], g.fraction[c2], g.offset[c2], u[two], ll[two],
                                          h[two], dirs[rows[two], li[two]])
                local2 = point_in_limb(u[two], ll[two], new_fraction[two], lower2, q2)
                p2 = root[two] + np.einsum("kij,kj->ki", frame[two], local2)
                frame[two] = turn_about_axis(root[two], point[two], p2, g.goal[c2]) @ frame[two]
            frames[rows, li] = frame
            fractions[rows, li] = new_fraction
            # A foot held where ground adaptation put it keeps its world direction too (its toes
            # must not dip into the ground as the leg re-aims); a constrained leg's foot turns
            # with the leg.
            held = np.flatnonzero(g.table_index[c] < 0)
            if held.size:
                rh, lh = rows[held], li[held]
                mid, end = two_bone_middle(frame[held], root[held], u[held], ll[held],
                                           new_fraction[held] * (u[held] + ll[held]))
                lower2world = distal_frames(frame[held], mid, end)
                dirs[rh, lh] = np.einsum("kji,kj->ki", lower2world, self.foot_in_world[rh, lh])
            self._limb_joints(rows, li, frames, fractions, dirs)
        rows_o, li_o = np.nonzero((self.orient_limb >= 0) & self.active[:, None])
        if rows_o.size:
            # The foot / hand axis, in its lower bone's frame (the ankle / wrist stays).
            mid = dec.positions[rows_o, LIMB_J[1][li_o]]
            end = dec.positions[rows_o, LIMB_J[2][li_o]]
            lower2world = distal_frames(frames[rows_o, li_o], mid, end)
            goal = g.goal[self.orient_limb[rows_o, li_o]]
            dirs[rows_o, li_o] = normalize(np.einsum("kji,kj->ki", lower2world, goal))
            self._limb_joints(rows_o, li_o, frames, fractions, dirs)
        if rows.size == 0 and rows_o.size == 0:
            return
        rows_c, li_c = np.concatenate([rows, rows_o]), np.concatenate([li, li_o])
        parent = np.where((li_c < 2)[:, None, None], dec.pelvis2world[rows_c], dec.thorax2world[rows_c])
        local = np.concatenate([poses.leg_frame, poses.arm_frame], axis=1)
        local[rows_c, li_c] = quat_from_matrix(np.swapaxes(parent, -1, -2) @ frames[rows_c, li_c])
        poses.leg_frame, poses.arm_frame = local[:, :2].copy(), local[:, 2:].copy()
        poses.leg_fraction, poses.arm_fraction = fractions[:, :2].copy(), fractions[:, 2:].copy()
        poses.foot_dir, poses.hand_dir = dirs[:, :2].copy(), dirs[:, 2:].copy()
        dec.leg2world, dec.arm2world = frames[:, :2].copy(), frames[:, 2:].copy()

    def _limb_joints(self, rows: I64, li: I64, frames: F64, fractions: F64, dirs: F64) -> None:
        """Middle, end and distal joints of the given (row, limb) pairs, from their frames."""
        dec = self.dec
        u, ll, h = (self.lengths[rows, LIMB_LENGTHS[k][li]] for k in range(3))
        frame = frames[rows, li]
        mid, end = two_bone_middle(frame, dec.positions[rows, LIMB_J[0][li]], u, ll,
                                   fractions[rows, li] * (u + ll))
        lower2world = distal_frames(frame, mid, end)
        dec.positions[rows, LIMB_J[1][li]] = mid
        dec.positions[rows, LIMB_J[2][li]] = end
        dec.positions[rows, LIMB_J[3][li]] = end + np.einsum(
            "kij,kj->ki", lower2world, dirs[rows, li]) * h[:, None]

    # --- head: neck and head as a two-segment chain; then its orientation ------------------
    def head(self) -> None:
        dec, poses, g = self.dec, self.poses, self.g
        first, orient = self.first_head, self.orient_head
        rows = np.flatnonzero(((first >= 0) | (orient >= 0)) & self.active)
        if rows.size == 0:
            return
        neck, head = dec.positions[rows, J["neck"]], dec.positions[rows, J["head"]].copy()
        head2world = dec.head2world[rows].copy()
        has_point = first[rows] >= 0
        p = np.flatnonzero(has_point)
        if p.size:
            # Neck and head are two segments from the neck's base, like a limb: the same
            # analytic step (flexion at the skull base, then aim), exact where reachable.
            c, rp = first[rows[p]], rows[p]
            u, ll = self.lengths[rp, L["neck"]], self.lengths[rp, L["head"]]
            top = dec.positions[rp, J["head_top"]]
            thorax_forward = dec.thorax2world[rp][:, :, 0]
            frame = frame_from_axes(top - neck[p], head[p] - neck[p], 2, 1,
                                    fallback_secondary=thorax_forward)
            lower = frame_from_axes(top - head[p], frame[:, :, 0], 2, 0,
                                    fallback_secondary=frame[:, :, 1])
            fraction = np.linalg.norm(top - neck[p], axis=1) / (u + ll)
            on_head = g.bone[c] == 1
            # The point in its bone's frame (offsets are given in the head's / thorax's frame).
            along = g.fraction[c] * np.where(on_head, ll, u)
            offset_world = np.einsum("kij,kj->ki", np.where(on_head[:, None, None], head2world[p],
                                                            dec.thorax2world[rp]), g.offset[c])
            upper_bone = frame_from_axes(head[p] - neck[p], frame[:, :, 0], 2, 0,
                                         fallback_secondary=frame[:, :, 1])
            bone = np.where(on_head[:, None, None], lower, upper_bone)
            q = np.einsum("kji,kj->ki", bone, offset_world)
            q[:, 2] += along
            new_frame, new_fraction, _ = reach_point(neck[p], frame, u, ll, fraction, on_head, q, g.goal[c])
            new_head, new_top = two_bone_middle(new_frame, neck[p], u, ll, new_fraction * (u + ll))
            new_lower = frame_from_axes(new_top - new_head, new_frame[:, :, 0], 2, 0,
                                        fallback_secondary=new_frame[:, :, 1])
            # The head turns as its bone does (twist included, through the plane's normal).
            head2world[p] = new_lower @ np.swapaxes(lower, -1, -2) @ head2world[p]
            head[p] = new_head
        o = np.flatnonzero(orient[rows] >= 0)
        if o.size:
            c = orient[rows[o]]
            axis = np.einsum("kij,kj->ki", head2world[o], g.axis[c])
            head2world[o] = rotation_toward(axis, g.goal[c]) @ head2world[o]
        thorax_t = np.swapaxes(dec.thorax2world[rows], -1, -2)
        neck_len = self.lengths[rows, L["neck"]]
        poses.neck_dir[rows] = np.einsum("kij,kj->ki", thorax_t, (head - neck) / neck_len[:, None])
        poses.head[rows] = quat_from_matrix(thorax_t @ head2world)
        dec.head2world[rows] = head2world
        dec.positions[rows, J["head"]] = head
        dec.positions[rows, J["head_top"]] = head + np.einsum(
            "kij,kj->ki", head2world, poses.head_top_dir[rows]) * self.lengths[rows, L["head"], None]

    # --- trunk: CCD about the spine's base ----------------------------------------------------
    def trunk(self) -> None:
        dec, poses, g, s = self.dec, self.poses, self.g, self.s
        carried = np.isin(g.group, ABOVE_TRUNK)
        uses_trunk = (g.chain & (1 << TRUNK)) > 0
        err = _errors(g, dec)
        tol = np.where(g.orientation, s.tolerance_rad, s.tolerance_m)
        candidates = uses_trunk & carried & (err > tol) & ~self.stalled & self.active[g.owner]
        best = winners(g.owner, np.zeros(g.k, np.int64), g.priority, candidates, self.r, 1)[:, 0]
        rows = np.flatnonzero(best >= 0)
        if rows.size == 0:
            return
        c = best[rows]
        base = dec.positions[rows, J["pelvis"]]
        point = point_positions(dec, rows, g.segment[c], g.fraction[c], g.offset[c])
        turn = rotation_toward(point - base, g.goal[c] - base, s.max_ccd_step_rad)
        # A head or arm point its limb cannot reach from where the limb's root is: turn the trunk
        # to bring that root (neck, shoulder) within reach rather than the point onto the goal.
        limb_root = LIMB_ROOT_JOINT[g.group[c]]
        far = (limb_root >= 0) & ~g.orientation[c]
        if far.any():
            f = np.flatnonzero(far)
            root_at = dec.positions[rows[f], limb_root[f]]
            middle_at = dec.positions[rows[f], LIMB_MIDDLE_JOINT[g.group[c[f]]]]
            # A point on the limb's first bone (upper arm, neck) keeps its distance from the
            # root: the root must come exactly that far from the goal. One further out reaches
            # up to the first bone's length plus its distance from the middle joint.
            first_bone = g.bone[c[f]] == 0
            reach = np.where(
                first_bone, np.linalg.norm(point[f] - root_at, axis=1),
                LIMB_REACH_SHARE * (np.linalg.norm(middle_at - root_at, axis=1)
                                    + np.linalg.norm(point[f] - middle_at, axis=1)))
            short = np.linalg.norm(g.goal[c[f]] - root_at, axis=1) > reach
            f = f[short]
            turn[f] = bring_within_reach(base[f], root_at[short], g.goal[c[f]], reach[short],
                                         s.max_ccd_step_rad)
        o = g.orientation[c]
        if o.any():
            frames = segment_frames(dec, rows[o], g.segment[c[o]])
            axis = np.einsum("kij,kj->ki", frames, g.axis[c[o]])
            turn[o] = rotation_toward(axis, g.goal[c[o]], s.max_ccd_step_rad)
        # Spread the turn along the spine (a third, two thirds, all of it at the neck); the thorax,
        # and all it carries, turns by all of it.
        spine_before, thorax_before = poses.spine_points[rows].copy(), poses.thorax[rows].copy()
        pelvis_t = np.swapaxes(dec.pelvis2world[rows], -1, -2)
        turn_in_pelvis = pelvis_t @ turn @ dec.pelvis2world[rows]
        axis, angle = _axis_angle_of(turn_in_pelvis)
        for k in range(3):  # the three spine control points
            part = axis_angle(axis, angle * (k + 1) / 3.0)
            poses.spine_points[rows, k] = np.einsum("kij,kj->ki", part, poses.spine_points[rows, k])
        thorax = turn_in_pelvis @ matrix_from_quat(poses.thorax[rows])
        poses.thorax[rows] = quat_from_matrix(thorax)
        self._decode(rows)
        # A move that worsens any higher-priority goal the trunk carries is undone. Measured on
        # the decoded result: the vertebrae keep their lengths along the bent spline, so the
        # neck, and all the trunk carries, does not end where a rigid turn about the pelvis
        # would take it (a lower-priority goal's turns drifted an unreachable elbow's by 2.6 mm).
        winner_priority = np.full(self.r, np.inf)
        winner_priority[rows] = g.priority[c]
        h = np.flatnonzero(carried & self.is_point & (g.priority > winner_priority[g.owner]))
        if h.size:
            point_h = point_positions(dec, g.owner[h], g.segment[h], g.fraction[h], g.offset[h])
            after = np.linalg.norm(point_h - g.goal[h], axis=1)
            # A goal its limb (or the neck and head) meets first is met again by the next pass
            # wherever the turn carried it: what the pass cannot make up is how far the goal
            # is beyond the limb's reach from where the turn left its root.
            first = self.is_first[h]
            if first.any():
                f, owner = h[first], g.owner[h[first]]
                root_at = dec.positions[owner, LIMB_ROOT_JOINT[g.group[f]]]
                middle_at = dec.positions[owner, LIMB_MIDDLE_JOINT[g.group[f]]]
                on_first_bone = g.bone[f] == 0
                reach = np.where(on_first_bone, np.linalg.norm(point_h[first] - root_at, axis=1),
                                 np.linalg.norm(middle_at - root_at, axis=1)
                                 + np.linalg.norm(point_h[first] - middle_at, axis=1))
                after[first] = np.maximum(np.linalg.norm(g.goal[f] - root_at, axis=1) - reach, 0.0)
            worse = after > err[h] + s.tolerance_m
            undo = np.isin(rows, g.owner[h][worse])
            if undo.any():
                back = rows[undo]
                poses.spine_points[back], poses.thorax[back] = spine_before[undo], thorax_before[undo]
                self._decode(back)

    # --- root: adaptRoot, the centre of mass back over its desired place ----------------------
    def com_shortfall(self) -> F64:
        """(r, 2) the horizontal way from each centre of mass to its desired place (m; 0 without
        COM control)."""
        com = centres_of_mass(self.dec.positions, self.masses, self.com_fraction)
        error: F64 = self.g.com_desired[:, :2] - com[:, :2]
        error[~self.g.com_on] = 0.0
        return error

    def root(self) -> F64:
        """Move the root horizontally to bring the centre of mass back (:meth:`root_move`);
        lower it if a planted leg could no longer reach its footprint. Returns (r,) the error
        before (m)."""
        dec, poses, s = self.dec, self.poses, self.s
        error = self.com_shortfall()
        size: F64 = np.linalg.norm(error, axis=1)
        rows = np.flatnonzero((size > 0.1 * s.com_tolerance_m) & self.active)
        if rows.size == 0:
            return size
        shift = self.root_move(rows, error[rows])
        poses.root_position[rows] += shift / leg_length(self.lengths[rows])[:, None]
        # A translation of the root moves every joint by it (the legs re-aim next).
        dec.positions[rows] += shift[:, None]
        return size

    def _with_lowering(self, rows: I64, horizontal: F64) -> F64:
        """(n, 3) the root's move for a horizontal one (n, 2) m: lowered where a planted leg
        could no longer reach its footprint from the moved hip."""
        g = self.g
        shift = np.zeros((rows.size, 3))
        shift[:, :2] = horizontal
        hips = self.dec.positions[rows][:, list(SIDE_JOINTS["hip"])] + shift[:, None]
        lengths = self.lengths[rows]
        reach = MAX_LEG_EXTENSION * (lengths[:, SIDE_LENGTHS["thigh"]] + lengths[:, SIDE_LENGTHS["shank"]])
        needed = vertical_slack_for_reach(hips, g.footprint[rows], reach)
        shift[:, 2] = np.min(np.where(g.in_contact[rows], np.minimum(needed, 0.0), 0.0), axis=1)
        return shift

    def root_move(self, rows: I64, error: F64) -> F64:
        """(n, 3) the root's move (m) that brings the centre of mass of ``rows`` (n,) by
        ``error`` (n, 2) once the next pass has put the legs back on their goals: the legs
        whose ankle the pass keeps where it is (:meth:`held_legs`: the planted feet) re-bend
        (:func:`middle_after_root_move`), the rest of the body moves with the root. Newton's
        step on that prediction (its Jacobian by a 1 mm probe along x and y), corrected once by
        the prediction at that step. Where no step can be predicted (a held ankle beyond its
        leg's reach from there, or a degenerate Jacobian) the root moves by the error times
        ``root_gain``; so it does for a character with a goal that keeps it iterating anyway
        or a goal aiming at the world or at another character (not :attr:`predicted`): where
        such goals stall (an error unchanged from one iteration to the next) depends on the
        root's moves, and predicted ones changed, directly or through the next ticks, where
        an unreachable elbow stopped by 14 mm (``reach_and_touch.yaml``) and how far a head
        stayed from its area by 8 mm (``fight_training.yaml``)."""
        dec, s = self.dec, self.s
        held = self.held_legs(rows)
        p = dec.positions[rows]
        hip, knee, ankle = (p[:, LIMB_J[k][:2]] for k in range(3))  # (n, 2, 3)
        lengths = self.lengths[rows]
        thigh, shank = (lengths[:, LIMB_LENGTHS[k][:2]] for k in range(2))  # (n, 2)
        masses, fraction = self.masses[rows], self.com_fraction[rows]
        total = masses.sum(axis=1)[:, None]
        thigh_m, shank_m, foot_m = (masses[:, LIMB_MASS[:2, k]] / total for k in range(3))
        thigh_f, shank_f = fraction[:, LIMB_MASS[:2, 0]], fraction[:, LIMB_MASS[:2, 1]]
        # (n, 2) the shares of the body's mass that move with each held leg's knee (its
        # bones' centres of mass weighted by how near to it each lies) and that stay with its
        # ankle (the rest of the shank, the foot)
        knee_share = np.where(held, thigh_m * thigh_f + shank_m * (1.0 - shank_f), 0.0)
        ankle_share = np.where(held, shank_m * shank_f + foot_m, 0.0)
        rigid = 1.0 - np.sum(knee_share + ankle_share, axis=1)

        def com_move(move: F64) -> F64:
            # (n, 2) the centre of mass's move once the held legs re-bend after the root's move
            moved = middle_after_root_move(hip, ankle, dec.leg2world[rows], thigh, shank,
                                           np.broadcast_to(move[:, None], hip.shape))
            bend = np.einsum("nl,nlc->nc", knee_share,
                             np.where(held[..., None], moved[..., :2] - knee[..., :2], 0.0))
            out: F64 = move[:, :2] * rigid[:, None] + bend
            return out

        probe = np.zeros((rows.size, 3))
        probe[:, 0] = ROOT_PROBE_M
        along_x = com_move(probe) / ROOT_PROBE_M
        probe[:, :] = 0.0
        probe[:, 1] = ROOT_PROBE_M
        along_y = com_move(probe) / ROOT_PROBE_M
        det = along_x[:, 0] * along_y[:, 1] - along_y[:, 0] * along_x[:, 1]
        ok = det > MIN_ROOT_JACOBIAN

        def newton(e: F64) -> F64:
            # (n, 2) the Jacobian's inverse applied to e (Cramer's rule)
            safe = np.where(ok, det, 1.0)
            return np.stack([(along_y[:, 1] * e[:, 0] - along_y[:, 0] * e[:, 1]) / safe,
                             (along_x[:, 0] * e[:, 1] - along_x[:, 1] * e[:, 0]) / safe], axis=1)

        step = self._with_lowering(rows, newton(error))
        beyond = np.linalg.norm(ankle - hip - step[:, None], axis=2) > (
            MAX_LEG_EXTENSION * (thigh + shank) * (1.0 + 1e-9))
        ok &= ~np.any(held & beyond, axis=1)  # the prediction holds while the ankles stay in reach
        ok &= self.predicted[rows]
        shift = self._with_lowering(rows, step[:, :2] + newton(error - com_move(step)))
        if not ok.all():
            fallback = np.flatnonzero(~ok)
            shift[fallback] = self._with_lowering(rows[fallback], error[fallback] * s.root_gain)
        return shift

    def held_legs(self, rows: I64) -> NDArray[np.bool_]:
        """(n, 2) the legs of ``rows`` whose ankle the next pass keeps where it is: the leg's
        goal is a world point at the ankle (a planted foot's), met now, and it has no second
        goal."""
        g = self.g
        first = self.first_limb[rows, :2]
        j = np.maximum(first, 0)
        ankle_now = self.dec.positions[rows[:, None], LIMB_J[2][:2]]
        at_ankle = ((first >= 0) & (self.second_limb[rows, :2] < 0) & ~g.orientation[j]
                    & ~self.follows_body[j] & (g.bone[j] == 1) & (g.fraction[j] == 1.0)
                    & np.all(g.offset[j] == 0.0, axis=2))
        held: NDArray[np.bool_] = at_ankle & (
            np.linalg.norm(ankle_now - g.goal[j], axis=2) <= self.s.tolerance_m * 0.01)
        return held


def _bone_coords(bone: I64, fraction: F64, offset: F64, upper: F64, lower: F64, distal: F64,
                 distal_dir: F64) -> tuple[F64, NDArray[np.bool_]]:
    """Limb points in their bone's frame (k, 3) (a foot / hand point in its lower bone's frame,
    through the distal direction ``distal_dir`` (k, 3)), and whether they move with the lower
    bone (k,). ``bone`` 0 upper, 1 lower, 2 distal; lengths (k,) metres."""
    q = offset.copy()
    q[:, 2] += fraction * np.where(bone == 0, upper, np.where(bone == 1, lower, distal))
    on_distal = bone == 2
    if on_distal.any():
        frame = _distal_in_lower(distal_dir[on_distal])
        q[on_distal] = np.einsum("kij,kj->ki", frame, q[on_distal])
        q[on_distal, 2] += lower[on_distal]
    return q, bone >= 1


def _distal_in_lower(dirs: F64) -> F64:
    """Frames (k, 3, 3) of a foot / hand in its lower bone's frame: z along ``dirs``, x the
    limb normal (made orthogonal)."""
    x = np.broadcast_to(np.array([1.0, 0.0, 0.0]), dirs.shape)
    return frame_from_axes(dirs, x, 2, 0, fallback_secondary=np.broadcast_to([0.0, 1.0, 0.0], dirs.shape))


def _axis_angle_of(rotation: F64) -> tuple[F64, F64]:
    """Unit axis (k, 3) and angle (k,) of rotation matrices (angles below π)."""
    axis = np.stack([rotation[:, 2, 1] - rotation[:, 1, 2], rotation[:, 0, 2] - rotation[:, 2, 0],
                     rotation[:, 1, 0] - rotation[:, 0, 1]], axis=1)
    sin2 = np.linalg.norm(axis, axis=1)
    cos = np.trace(rotation, axis1=1, axis2=2) - 1.0
    angle = np.arctan2(sin2, cos)
    return normalize(axis), angle


def solve(poses: NormalizedPoses, lengths: F64, goals: TickGoals, masses: F64, com_fraction: F64,
          settings: SolverSettings = DEFAULT_SETTINGS, decoded: DecodedPose | None = None,
          in_place: bool = False) -> tuple[NormalizedPoses, I64, DecodedPose]:
    """Solve this tick's goals for their characters (rows of ``poses``, ``lengths``, ``masses``
    and ``com_fraction`` are ``goals.rows``; ``decoded`` is ``decode(poses, lengths)`` if the
    caller has it). Returns the new poses, the iterations each character used (r,), and the
    decoded result (joint positions (r, N_JOINTS, 3) and frames), on which :func:`constraint_errors` measures each
    constraint. With ``in_place`` the given ``poses`` and ``decoded`` are the caller's scratch
    copies, solved in place (as the compiled solve does; here they are copied all the same)."""
    state = _Solve(poses, lengths, goals, masses, com_fraction, settings, decoded)
    tol = np.where(goals.orientation, settings.tolerance_rad, settings.tolerance_m)
    previous = np.full(goals.k, np.inf)
    slow_before = np.zeros(goals.k, bool)
    # Only goals an iteration still moves can keep a character's loop going: the trunk's (it
    # turns a step at a time) and those following a point of their own body that the passes
    # move; the passes (limbs and head, analytic) meet the others as well as they can be met.
    iterative = ((goals.chain & (1 << TRUNK)) > 0)
    iterative[goals.on_self] |= SEGMENT_MOVED_BY_PASS[goals.self_segment]
    state.predicted[goals.owner[iterative | ((goals.table_index >= 0) & ~state.follows_body)]] = False
    used = np.zeros(state.r, np.int64)
    goal_caps, row_caps = iteration_caps(goals, settings)
    # Characters with a goal left open at the last measure (before the first: any iterative).
    open_rows = np.zeros(state.r, bool)
    open_rows[goals.owner[iterative]] = True
    while True:
        # A pass: legs, head, arms (the paper's order; legs and arms are independent, so one
        # batch) re-planted and re-aimed after the last root move and trunk turn.
        state.follow_own_targets()
        state.limbs()
        state.head()
        # The pass is the result where no iteration would change anything: no goal left open,
        # and the centre of mass so close that the root step would not move (a tenth of its
        # tolerance); or the budget spent. Finished characters are no longer stepped.
        state.active &= used < row_caps
        com_error = np.linalg.norm(state.com_shortfall(), axis=1)
        state.active &= open_rows | (com_error > 0.1 * settings.com_tolerance_m)
        if not state.active.any():
            break
        # An iteration: the trunk turns for the open goals it carries, the root moves the centre
        # of mass back.
        used += state.active
        state.trunk()
        state.root()
        # A goal is open where not met nor stalled (unchanged, or falling by less than a share
        # of itself twice running: unreachable; a stalled goal stays stalled).
        err = _errors(goals, state.dec)
        first = np.isinf(previous)
        unchanged = ~first & (np.abs(previous - err) < settings.tolerance_m)
        slow = ~first & (previous - err < settings.stall_fraction * np.where(first, 0.0, previous))
        cut = used[goals.owner] >= goal_caps  # the frame budget gave it no more iterations
        goal_open = ((err > tol) & iterative & ~unchanged & ~(slow & slow_before) & ~state.stalled
                     & ~cut)
        stepped = state.active[goals.owner] & iterative
        state.stalled |= (err > tol) & ~goal_open & stepped
        previous = np.where(stepped, err, previous)
        slow_before = np.where(stepped, slow, slow_before)
        open_rows[:] = False
        open_rows[goals.owner[goal_open]] = True
    return state.poses, used, state.dec


@dataclass
class TickResult:
    """What :func:`constrain` decided this tick, for the system to write back.

    weight (m,) each constraint's activation (0 where switched off); broken (b,) constraints
    whose target is not finite or beyond :data:`MAX_TARGET_M`, to switch off; error (m,) how far each active constraint is from
    being met on the result (:func:`constraint_errors`; NaN while inactive); held (m,) a sphere
    kept the point off the motion's place; goals, rows (r,), poses (r,), solved (decoded
    result (r,)) and iterations (r,) of the characters solved (None / empty when none); cut:
    what the frame budget cut (None: nothing to decide: no budget, no model or no goal);
    solve_s: the wall time the solve itself took (s), for the cost model's calibration."""

    weight: F64
    broken: I64
    error: F64
    held: NDArray[np.bool_]
    goals: TickGoals | None = None
    rows: I64 = field(default_factory=lambda: np.zeros(0, np.int64))
    poses: NormalizedPoses | None = None
    solved: DecodedPose | None = None
    iterations: I64 | None = None
    cut: BudgetCut | None = None
    solve_s: float = 0.0


class TickSteps(NamedTuple):
    """The computations one tick of :func:`constrain` is made of, each a function of the
    signature of its numpy reference here: ``goals`` (:func:`tick_goals`), ``solve``
    (:func:`solve`), ``errors`` (:func:`constraint_errors`), ``centres``
    (:func:`ecs_anim.core.morphology.centres_of_mass`), ``targets`` (:func:`target_points`),
    ``result_errors`` (:func:`errors_on_result`: the errors on the solve's result) and
    ``surfaces`` (:func:`on_other_surfaces`).
    :data:`NUMPY_STEPS` are those references; ConstraintSolve runs the compiled ones
    (:mod:`ecs_anim.runtime.kernels.goals`, :func:`ecs_anim.runtime.kernels.solve.solve`)."""

    goals: Callable[..., TickGoals | None]
    solve: Callable[..., tuple[NormalizedPoses, I64, DecodedPose]]
    errors: Callable[[ConstraintTable, I64, DecodedPose, F64], F64]
    centres: Callable[[F64, F64, F64], F64]
    targets: Callable[..., F64] = target_points
    result_errors: Callable[[ConstraintTable, I64, DecodedPose, F64], F64] = errors_on_result
    surfaces: Callable[..., F64] = on_other_surfaces


NUMPY_STEPS = TickSteps(tick_goals, solve, constraint_errors, centres_of_mass, target_points,
                        errors_on_result, on_other_surfaces)


def focus_distances(positions: F64, focus_in_world: tuple[float, float, float] | None) -> F64:
    """(r,) each character's pelvis distance from the focus point (m); zeros without one.
    ``positions`` (r, N_JOINTS, 3)."""
    if focus_in_world is None:
        return np.zeros(positions.shape[0])
    distance: F64 = np.linalg.norm(positions[:, J["pelvis"]] - np.asarray(focus_in_world), axis=1)
    return distance


def constrain(table: ConstraintTable, weight: F64, poses: NormalizedPoses,
              unconstrained: DecodedPose | None,
              lengths: F64, contact_weight: F64, com_control: NDArray[np.bool_], com_target_xy: F64,
              masses: F64, com_fraction: F64, previous: DecodedPose | None,
              settings: SolverSettings, max_release_m: float, steps: TickSteps,
              model: SolverCostModel | None = None,
              expected_iterations: I64 | None = None) -> TickResult:
    """One tick of ConstraintSolve's policy over every character (n rows): the targets, the
    constraints switched off (a target not finite), the desired centre of mass (the motion's own,
    or ``com_target_xy`` (n, 2) where finite), the goals, the frame budget's cut, the solve of
    the characters with an active constraint, and every active constraint's error on the
    result; ``steps`` computes the goals, the solve, the errors and the centres of mass (the
    numpy references, :data:`NUMPY_STEPS`, or the compiled ones).

    ``weight`` (m,) this tick's activations; ``poses`` (n,) this tick's, solved in place when
    every character is solved; ``unconstrained`` the decoded ``poses`` (None only when no weight
    is above 0), this call's own: its solved rows are overwritten with the result; masses and com_fraction (n, S); ``previous`` the last tick's posture (None on the
    first). With ``settings.budget_ms`` and a ``model`` (the
    settings' own ``cost_model`` first), :func:`ecs_anim.solver.budget.cut_to_budget` decides
    the iterations; ``expected_iterations`` (n,) what each character took last tick (0: not
    solved: the settings' ``iterations``)."""
    m = table.m
    error = np.full(m, np.nan)
    held = np.zeros(m, bool)
    none = np.zeros(0, np.int64)
    if not np.any(weight > 0):
        return TickResult(weight, none, error, held)
    if unconstrained is None:
        raise ValueError("constrain: the decoded poses are needed when a constraint is active")
    targets = steps.surfaces(table, steps.targets(table, unconstrained, previous, weight > 0),
                             lengths, unconstrained, previous)
    broken = none
    # (one test of the whole array first, its largest and least (no array of their absolute
    # values): the usual case; NaN fails it too)
    if not (targets.max() <= MAX_TARGET_M and targets.min() >= -MAX_TARGET_M):
        broken = np.flatnonzero((weight > 0) & ~np.all(np.abs(targets) <= MAX_TARGET_M, axis=1))
    if broken.size:
        weight = weight.copy()
        weight[broken] = 0.0
        targets[broken] = 0.0
    own = steps.centres(unconstrained.positions, masses, com_fraction)
    if np.isfinite(com_target_xy).any():  # (usually none is given: all NaN)
        given = np.isfinite(com_target_xy).all(axis=1)
        own[given, :2] = com_target_xy[given]
    goals = steps.goals(table, weight, targets, unconstrained, contact_weight, com_control, own,
                        previous, max_release_m)
    active = np.flatnonzero(weight > 0)
    if goals is None:  # only areas the motion already keeps
        error[active] = steps.errors(table, active, unconstrained, targets)
        return TickResult(weight, broken, error, held)
    rows = goals.rows
    every_row = rows.size == lengths.shape[0]
    cut = None
    model = settings.cost_model or model
    if settings.budget_ms is not None and model is not None:
        expected = (np.full(rows.size, settings.iterations, np.int64) if expected_iterations is None
                    else expected_iterations[rows])
        expected = np.where(expected > 0, expected, settings.iterations)
        cut = cut_to_budget(goals, expected,
                            focus_distances(unconstrained.positions[rows], settings.focus_in_world),
                            settings.budget_ms, model, settings.iterations)
        goals.goal_iterations, goals.row_iterations = cut.goal_iterations, cut.row_iterations
    # The solve works on copies of its rows; when every character is solved, on the poses and
    # the decoded poses themselves (the store's pose of this tick, which the result replaces
    # anyway, and this call's own), and on the bodies as they are (it only reads them).
    start = time.perf_counter()
    if every_row:
        solved_poses, iterations, solved = steps.solve(
            poses, lengths, goals, masses, com_fraction, settings, unconstrained, True)
    else:
        solved_poses, iterations, solved = steps.solve(
            poses.take(rows), lengths[rows], goals, masses[rows], com_fraction[rows], settings,
            unconstrained.take(rows), True)
    solve_s = time.perf_counter() - start
    # (the feet's goals, table_index -1, written into one place more and dropped: no masks of
    # the user goals to gather with; each constraint is one goal at most. Usually no goal is
    # held: no scatter of the k goals)
    if goals.held.any():
        with_feet = np.zeros(m + 1, bool)
        with_feet[goals.table_index] = goals.held
        held = with_feet[:m]
    # Every active constraint's error on the result (an area the motion already kept was not a
    # goal, but another constraint's move may have taken its point out).
    result = unconstrained
    if solved.positions is not result.positions:  # not solved in place
        for name in fields(DecodedPose):
            getattr(result, name.name)[rows] = getattr(solved, name.name)
    # (targets on the character's own body moved with it during the solve: read again)
    result_error = steps.result_errors(table, active, result, targets)
    if active.size == m:  # (every constraint active: sorted, distinct, all; no scatter)
        error = result_error
    else:
        error[active] = result_error
    return TickResult(weight, broken, error, held, goals, rows, solved_poses, solved, iterations,
                      cut, solve_s)


def scatter(all_poses: NormalizedPoses, rows: I64, part: NormalizedPoses) -> NormalizedPoses:
    """``all_poses`` with ``rows`` replaced by ``part`` (new arrays)."""
    arrays = {}
    for name, value in all_poses.arrays().items():
        new = value.copy()
        new[rows] = getattr(part, name)
        arrays[name] = new
    return NormalizedPoses(**arrays)


__all__ = ["SolverSettings", "TickResult", "TickSteps", "constrain", "iteration_caps", "scatter",
           "solve"]
