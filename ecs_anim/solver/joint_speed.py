"""No pops: how much faster than its motion the solver may move a joint from one tick to the next.

The solver may change a pose a lot between two ticks while its goals hardly move: a trunk that
a chain may bend folds 60° in one tick once a punch's target is out of the arm's reach, a leg
twists about its hip-ankle axis as a kick's goal eases in (the knee's correction changing at
14.5 m/s, the toe at 16.8 m/s where the clip's moves at 3), a short ease snaps the arm to its
goal. What the solver adds to the motion is each joint's *correction*: how
far it puts the joint from where the motion has it. The bound: no joint, measured from its
pelvis (:func:`from_pelvis`: the root's own move and the centre of mass's count for nothing),
steps further in a tick than the motion's own joint steps plus ``max_step_m``
(``SolverSettings.max_joint_speed_m_s * dt``). So:

* the motion's own fast moves (a kick) and a correction that keeps a point on a target while the
  motion sweeps past it (the correction changing as fast as the motion, the joint standing
  still) are not touched, nor a point following a fully active goal that moves fast (a
  forearm warding off a kicking ankle: a character's bound grows by its fastest such goal's
  step): only a joint faster than its motion's by more than that is. A ramp (a constraint
  easing in or out, where the solve may flip a knee or fold a trunk) is the bound's to spread;
  a constraint switched on at once (no ease) asks for the jump and gets it (its character's
  goal step is infinite on that tick);
* such a character's correction goes only a share of its way from the last tick's to this
  tick's solve, the same share in every segment the solver sets (:func:`step_shares`,
  :func:`limit_motion`): the share that brings its fastest joint to the bound, so the body keeps
  the solved shape along the way and a fold of the trunk is spread over several ticks. The
  share is taken in each segment's correction (its turn or shift away from the motion's own
  segment), so the motion plays on at its own speed while the correction catches up, never
  faster than the bound allows;
* a leg standing on a footprint (contact) is not limited and its joints do not count; the
  characters held back are solved again on their limited pose with the feet's goals alone
  (:func:`contact_goals`), which re-plants the feet and moves the root so that the centre of
  mass is back.

Segment values are packed per character into :data:`N_VALUES` floats (:func:`pack`): the six
frames' quaternions, the five directions, the thirteen fractions and spine coordinates. A row
of zeros means "no last tick" (no quaternion is zero): nothing to limit. This module is the
numpy reference of :mod:`ecs_anim.runtime.kernels.joint_speed` (same arguments, same results
to 1e-9).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import fields
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.body_points import ARM_L, ARM_R, HEAD, LEG_L, LEG_R, TRUNK
from ecs_anim.core.normalized import DecodedPose, NormalizedPoses, decode
from ecs_anim.core.rotations import quat_between, quat_conj, quat_mul, quat_rotate
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.solver.goals import CONTACT_PRIORITY, TickGoals
from ecs_anim.solver.shell import SolverSettings, solve

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
B8 = NDArray[np.bool_]

#: The frames the solver turns (pose field, side or -1, group): quaternions at
#: ``values[:, 4 k:4 k + 4]``.
FRAMES = (("leg_frame", 0, LEG_L), ("leg_frame", 1, LEG_R), ("arm_frame", 0, ARM_L),
          ("arm_frame", 1, ARM_R), ("thorax", -1, TRUNK), ("head", -1, HEAD))
#: The directions it turns: unit vectors at ``values[:, DIRECTIONS_AT + 3 k:...]``.
DIRECTIONS = (("foot_dir", 0, LEG_L), ("foot_dir", 1, LEG_R), ("hand_dir", 0, ARM_L),
              ("hand_dir", 1, ARM_R), ("neck_dir", -1, HEAD))
#: The values it shifts (pose field, index or -1, width, group): the limbs' fractions and the
#: spine's three points, at ``values[:, SHIFTS_AT + ...]``.
SHIFTS = (("leg_fraction", 0, 1, LEG_L), ("leg_fraction", 1, 1, LEG_R),
          ("arm_fraction", 0, 1, ARM_L), ("arm_fraction", 1, 1, ARM_R),
          ("spine_points", 0, 3, TRUNK), ("spine_points", 1, 3, TRUNK),
          ("spine_points", 2, 3, TRUNK))
DIRECTIONS_AT = 4 * len(FRAMES)
SHIFTS_AT = DIRECTIONS_AT + 3 * len(DIRECTIONS)
N_VALUES = SHIFTS_AT + sum(w for _, _, w, _ in SHIFTS)
N_GROUPS = 6
#: Each shift's start (len(SHIFTS) + 1,) in ``values[:, SHIFTS_AT:]``.
SHIFT_START = np.concatenate([[0], np.cumsum([w for _, _, w, _ in SHIFTS])]).astype(np.int64)
#: The group of each frame, direction and shift (for the compiled kernel).
FRAME_GROUP = np.array([g for *_, g in FRAMES], np.int64)
DIRECTION_GROUP = np.array([g for *_, g in DIRECTIONS], np.int64)
SHIFT_GROUP = np.array([g for *_, g in SHIFTS], np.int64)


def _rotvec_of(q: F64) -> F64:
    """Rotation vectors (..., 3), rad, of unit quaternions (..., 4) (the turn up to π)."""
    q = np.where(q[..., 3:] < 0.0, -q, q)
    s = np.linalg.norm(q[..., :3], axis=-1)
    per = np.where(s < 1e-12, 2.0, 2.0 * np.arctan2(s, q[..., 3]) / np.maximum(s, 1e-300))
    out: F64 = q[..., :3] * per[..., None]
    return out


def _quat_of(rotvec: F64) -> F64:
    """Unit quaternions (..., 4) of rotation vectors (..., 3), rad."""
    angle = np.linalg.norm(rotvec, axis=-1)
    per = np.where(angle < 1e-12, 0.5, np.sin(0.5 * angle) / np.maximum(angle, 1e-300))
    return np.concatenate([rotvec * per[..., None], np.cos(0.5 * angle)[..., None]], axis=-1)


def _get(poses: NormalizedPoses, field: str, index: int) -> F64:
    value: F64 = getattr(poses, field)
    return value if index < 0 else value[:, index]


def _set(poses: NormalizedPoses, field: str, index: int, rows: I64, value: F64) -> None:
    if index < 0:
        getattr(poses, field)[rows] = value
    else:
        getattr(poses, field)[rows, index] = value


def pack(poses: NormalizedPoses) -> F64:
    """(r, N_VALUES) the values of ``poses`` (r,) the solver sets, packed."""
    parts = [_get(poses, f, i) for f, i, _ in FRAMES] + [_get(poses, f, i) for f, i, _ in DIRECTIONS]
    parts += [_get(poses, f, i).reshape(-1, w) for f, i, w, _ in SHIFTS]
    return np.concatenate(parts, axis=1)


def rows_differ(values: F64, other: F64) -> B8:
    """(r,) whether each row of ``values`` (r, N_VALUES) differs from the same row of ``other``
    anywhere (a result whose segments are not the motion's own: a correction kept)."""
    out: B8 = np.any(values != other, axis=1)
    return out


def _frame_turns(a: F64, b: F64) -> F64:
    """Rotation vectors (r, 3) of the turns from quaternions ``a`` to ``b`` (r, 4)."""
    return _rotvec_of(quat_mul(b, quat_conj(a)))


#: Each leg's joints below the hip (knee, ankle, toe), [left, right]: a planted leg's do not
#: count in :func:`step_shares`.
LEG_JOINTS = ((J["knee_l"], J["ankle_l"], J["toe_l"]), (J["knee_r"], J["ankle_r"], J["toe_r"]))


def from_pelvis(positions: F64) -> F64:
    """(r, N_JOINTS, 3) m: the joints ``positions`` (r, N_JOINTS, 3, world m) from their own
    character's pelvis (so the root's own move, and the one the centre of mass asks, count for
    nothing in a joint's step)."""
    out: F64 = positions - positions[:, :1]
    return out


def goal_steps(goals: TickGoals, last_goals: F64, weight_before: F64) -> F64:
    """(r,) how far each of ``goals``' characters' fastest point goal fully active this tick and
    the last moved since (m; 0: none; a ramp's move is the bound's to spread), infinite for a
    character with a constraint switched on at once (fully active now, its weight at the last
    tick ``weight_before`` (m,) 0: its jump is asked for). ``last_goals`` (m, 3) each
    constraint's goal at the last tick if it was fully active then (NaN: it was not), made this
    tick's in place, for the next."""
    user = goals.table_index >= 0
    full = user & (goals.weight >= 1.0) & ~goals.orientation
    index = goals.table_index[full]
    moved = np.linalg.norm(goals.goal[full] - last_goals[index], axis=1)
    steps = np.zeros(goals.rows.size)
    np.maximum.at(steps, goals.owner[full], np.nan_to_num(moved, nan=0.0))
    at_once = np.zeros(goals.k, bool)
    at_once[user] = (goals.weight[user] >= 1.0) & (weight_before[goals.table_index[user]] <= 0.0)
    steps[goals.owner[at_once]] = np.inf
    last_goals[:] = np.nan
    last_goals[index] = goals.goal[full]
    return steps


def step_shares(pose_positions: F64, clip_positions: F64, pose_positions_before: F64,
                clip_positions_before: F64, planted: B8, max_step_m: float, goal_steps_m: F64
                ) -> F64:
    """(r,) the share of its way each character's correction may go, from the last tick's to
    this tick's solve, so that no joint steps more than ``max_step_m`` (m) plus how far the
    character's fastest fully active goal stepped (``goal_steps_m`` (r,), m: a joint may follow
    its goal) further than the motion's own joint does: the largest ``s`` in [0, 1] with
    ``|c + s d| <= |c| + max_step_m + goal_step`` for every joint, ``c`` the motion's step and
    ``d`` the correction's change (the joints' move is taken as linear in ``s``), both measured
    from the pelvis (:func:`from_pelvis`). All joints (r, N_JOINTS, 3) world m: this tick's
    solve ``pose_positions`` and motion ``clip_positions``, the last tick's result and motion
    (``..._before``; the pose's equal to the motion's where it was the motion's). The joints of
    the legs ``planted`` (r, 2) do not count."""
    clip_joints, clip_joints_before = from_pelvis(clip_positions), from_pelvis(clip_positions_before)
    clip_step = clip_joints - clip_joints_before
    change = ((from_pelvis(pose_positions) - clip_joints)
              - (from_pelvis(pose_positions_before) - clip_joints_before))
    allowed = np.linalg.norm(clip_step, axis=-1) + (max_step_m + goal_steps_m)[:, None]
    dd = np.sum(change * change, axis=-1)
    cd = np.sum(clip_step * change, axis=-1)
    # |c + s d|^2 = |c|^2 + 2 s c.d + s^2 |d|^2 <= allowed^2: the larger root (|c| < allowed)
    room = allowed * allowed - np.sum(clip_step * clip_step, axis=-1)
    # (a character whose goal jumped has an infinite room: no 0 * inf where nothing changes)
    largest = (-cd + np.sqrt(cd * cd + np.where(dd > 0.0, dd, 1.0) * room)) / np.maximum(dd, 1e-300)
    share = np.where(dd > 0.0, np.minimum(largest, 1.0), 1.0)
    for side, joints in enumerate(LEG_JOINTS):
        share[:, list(joints)] = np.where(planted[:, side, None], 1.0, share[:, list(joints)])
    out: F64 = share.min(axis=1, initial=1.0)
    return out


def limit_motion(poses: NormalizedPoses, clip_now: F64, clip_before: F64, pose_before: F64,
                 planted: B8, share: F64) -> tuple[NormalizedPoses, B8]:
    """``poses`` (r,), as the solve left them, with each segment's correction (its turn or
    shift away from the motion's own: ``clip_now`` for ``poses``, ``clip_before`` for
    ``pose_before``, the last tick's result; all (r, N_VALUES), packed; a row of zeros in
    ``pose_before``: no last tick) going only ``share`` (r,) of its way from the last tick's to
    this tick's, on the motion's segment of this tick. The legs of ``planted`` (r, 2) are left
    as solved. Returns the poses (new arrays) and (r,) whether anything was held back."""
    need = np.repeat(np.minimum(share, 1.0)[:, None], N_GROUPS, axis=1)
    need[:, [LEG_L, LEG_R]] = np.where(planted, 1.0, need[:, [LEG_L, LEG_R]])
    need[~np.any(pose_before != 0.0, axis=1)] = 1.0  # no last tick
    held = need < 1.0
    out = NormalizedPoses(**{k: v.copy() for k, v in poses.arrays().items()})
    for k, (field, index, group) in enumerate(FRAMES):
        rows = np.flatnonzero(held[:, group])
        if rows.size:
            at = slice(4 * k, 4 * k + 4)
            was = quat_mul(pose_before[rows, at], quat_conj(clip_before[rows, at]))
            now = quat_mul(_get(poses, field, index)[rows], quat_conj(clip_now[rows, at]))
            turn = _frame_turns(was, now) * need[rows, group, None]
            _set(out, field, index, rows, quat_mul(quat_mul(_quat_of(turn), was),
                                                    clip_now[rows, at]))
    for k, (field, index, group) in enumerate(DIRECTIONS):
        rows = np.flatnonzero(held[:, group])
        if rows.size:
            at = slice(DIRECTIONS_AT + 3 * k, DIRECTIONS_AT + 3 * k + 3)
            was = quat_between(clip_before[rows, at], pose_before[rows, at])
            now = quat_between(clip_now[rows, at], _get(poses, field, index)[rows])
            turn = _frame_turns(was, now) * need[rows, group, None]
            _set(out, field, index, rows,
                 quat_rotate(quat_mul(_quat_of(turn), was), clip_now[rows, at]))
    for k, (field, index, _, group) in enumerate(SHIFTS):
        rows = np.flatnonzero(held[:, group])
        if rows.size:
            at = slice(SHIFTS_AT + SHIFT_START[k], SHIFTS_AT + SHIFT_START[k + 1])
            to = _get(poses, field, index)[rows]
            shape = to.shape
            was = (pose_before[rows, at] - clip_before[rows, at]).reshape(shape)
            now = to - clip_now[rows, at].reshape(shape)
            part = need[rows, group].reshape((-1,) + (1,) * (to.ndim - 1))
            _set(out, field, index, rows, clip_now[rows, at].reshape(shape) + was + part * (now - was))
    any_held: B8 = np.any(held, axis=1)
    return out, any_held


def contact_goals(goals: TickGoals, rows: I64) -> TickGoals:
    """The goals of ``goals``' characters ``rows`` (local indices, sorted) that keep a planted
    foot on its footprint (priority :data:`~ecs_anim.solver.goals.CONTACT_PRIORITY`), with their
    centre-of-mass control: solved again on a limited pose, they re-plant the feet and move the
    root so the centre of mass is back, and turn nothing else."""
    local = np.full(goals.rows.size, -1, np.int64)
    local[rows] = np.arange(rows.size)
    keep = (goals.priority == CONTACT_PRIORITY) & (local[goals.owner] >= 0)
    no_ints = np.zeros(0, np.int64)
    return TickGoals(
        rows=goals.rows[rows], owner=local[goals.owner[keep]], table_index=goals.table_index[keep],
        orientation=goals.orientation[keep], group=goals.group[keep], bone=goals.bone[keep],
        segment=goals.segment[keep], fraction=goals.fraction[keep], offset=goals.offset[keep],
        chain=goals.chain[keep], priority=goals.priority[keep], goal=goals.goal[keep].copy(),
        weight=goals.weight[keep], axis=goals.axis[keep], footprint=goals.footprint[rows],
        in_contact=goals.in_contact[rows], com_desired=goals.com_desired[rows],
        com_on=goals.com_on[rows], on_self=no_ints, self_segment=no_ints,
        self_fraction=np.zeros(0), self_offset=np.zeros((0, 3)), self_start=np.zeros((0, 3)),
        held=goals.held[keep])


class MotionBefore(NamedTuple):
    """What :func:`solve_within_speed` compares this tick's solve with, for the rows it solves:
    ``clip_now`` and ``clip_before`` (r, N_VALUES) the motion's segments this tick and the
    last, ``pose_before`` (r, N_VALUES) the last tick's result (all packed); ``clip_positions``
    (r, N_JOINTS, 3) the motion's joints this tick, ``clip_positions_before`` and
    ``pose_positions_before`` the last tick's motion's and result's (all world m);
    ``goal_steps_m`` (r,) how far each character's fastest goal fully active at both ticks
    moved since the last (m; 0: none)."""

    clip_now: F64
    clip_before: F64
    pose_before: F64
    clip_positions: F64
    clip_positions_before: F64
    pose_positions_before: F64
    goal_steps_m: F64


def limit_again(limited: NormalizedPoses, rows: I64, before: MotionBefore, lengths: F64,
                planted: B8, max_step_m: float) -> tuple[NormalizedPoses, DecodedPose]:
    """The characters ``rows`` (local, sorted) that :func:`limit_motion` held back, taken out of
    ``limited`` (r,) and limited once more: the joints' move is not linear in the share
    (segments turn), so measured on the limited pose (decoded on ``lengths`` (r, N_LENGTHS)),
    the share (:func:`step_shares`, ``before`` and ``planted`` (r, 2) of all r) is taken once
    more of what is left over (a turn's share composes). Returns their poses (len(rows),), new
    arrays, and those poses decoded."""
    part = limited.take(rows)
    closer = step_shares(decode(part, lengths[rows]).positions, before.clip_positions[rows],
                         before.pose_positions_before[rows], before.clip_positions_before[rows],
                         planted[rows], max_step_m, before.goal_steps_m[rows])
    part, _ = limit_motion(part, before.clip_now[rows], before.clip_before[rows],
                           before.pose_before[rows], planted[rows], closer)
    return part, decode(part, lengths[rows])


def put_back(poses: NormalizedPoses, decoded: DecodedPose, rows: I64, part: NormalizedPoses,
             part_decoded: DecodedPose) -> None:
    """``poses`` and ``decoded`` (r,) with their ``rows`` replaced by ``part`` and
    ``part_decoded`` (len(rows),), in place."""
    for name, value in part.arrays().items():
        getattr(poses, name)[rows] = value
    for f in fields(DecodedPose):
        getattr(decoded, f.name)[rows] = getattr(part_decoded, f.name)


class SpeedSteps(NamedTuple):
    """The computations :func:`solve_within_speed` is made of, each with the signature of its
    numpy reference: ``solve`` (:func:`ecs_anim.solver.shell.solve`), ``shares``
    (:func:`step_shares`), ``limit`` (:func:`limit_motion`), ``again`` (:func:`limit_again`)
    and ``put`` (:func:`put_back`). :data:`NUMPY_SPEED_STEPS` are the references;
    ConstraintSolve runs the compiled ones."""

    solve: Callable[..., tuple[NormalizedPoses, I64, DecodedPose]]
    shares: Callable[..., F64]
    limit: Callable[..., tuple[NormalizedPoses, B8]]
    again: Callable[..., tuple[NormalizedPoses, DecodedPose]]
    put: Callable[..., None]


NUMPY_SPEED_STEPS = SpeedSteps(solve, step_shares, limit_motion, limit_again, put_back)


def solve_within_speed(steps: SpeedSteps, before: MotionBefore, max_step_m: float,
                       poses: NormalizedPoses, lengths: F64, goals: TickGoals, masses: F64,
                       com_fraction: F64, settings: SolverSettings,
                       decoded: DecodedPose | None = None, in_place: bool = False
                       ) -> tuple[NormalizedPoses, I64, DecodedPose]:
    """The solve of ``goals`` (the arguments from ``poses`` on are ``steps.solve``'s), then
    :func:`limit_motion` by the :func:`step_shares` that keep every joint's step within
    ``max_step_m`` (m) of the motion's own (plus its fastest goal's step); the characters held
    back are limited once more (:func:`limit_again`) and solved again on their limited pose
    with their feet's goals alone (:func:`contact_goals`: the feet re-planted, the centre of
    mass back). Returns what the solve does: the poses, the iterations each character used
    (both solves) and the decoded result."""
    solved, iterations, result = steps.solve(poses, lengths, goals, masses, com_fraction, settings,
                                             decoded, in_place)
    share = steps.shares(result.positions, before.clip_positions, before.pose_positions_before,
                         before.clip_positions_before, goals.in_contact, max_step_m,
                         before.goal_steps_m)
    if not (share < 1.0).any():  # (usually: no character's correction goes too fast)
        return solved, iterations, result  # (what the limit gives then: nothing held back)
    limited, held = steps.limit(solved, before.clip_now, before.clip_before, before.pose_before,
                                goals.in_contact, share)
    rows = np.flatnonzero(held)
    if rows.size == 0:
        return limited, iterations, result
    part, part_decoded = steps.again(limited, rows, before, lengths, goals.in_contact, max_step_m)
    again, more, part_decoded = steps.solve(
        part, lengths[rows], contact_goals(goals, rows), masses[rows], com_fraction[rows],
        settings, part_decoded, True)
    steps.put(limited, result, rows, again, part_decoded)
    iterations = iterations.copy()
    iterations[rows] += more
    return limited, iterations, result


__all__ = ["NUMPY_SPEED_STEPS", "N_VALUES", "MotionBefore", "SpeedSteps", "contact_goals",
           "from_pelvis", "goal_steps", "limit_again", "limit_motion", "pack", "put_back",
           "rows_differ", "solve_within_speed",
           "step_shares"]
