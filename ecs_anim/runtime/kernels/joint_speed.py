"""Compiled :mod:`ecs_anim.solver.joint_speed`: each segment's correction (its turn or shift
away from the motion's own) going only a share of its way from the last tick's (no pops).

:func:`step_shares`, :func:`limit_motion`, :func:`limit_again`, :func:`put_back`, :func:`pack`,
:func:`goal_steps` and :func:`rows_differ` take the arguments of their numpy references and give
the same results (to 1e-9); the per-character loops are :func:`share_rows`, :func:`limit_rows`,
:func:`again_rows`, :func:`put_rows`, :func:`pack_rows`, :func:`goal_steps_rows` and
:func:`differing_rows`.
Values are packed as the reference's: frames 0-5 (legs, arms, thorax, head) as quaternions,
directions 0-4 (feet, hands, neck), shifts 0-12 (leg fractions, arm fractions, the spine's
three points).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.normalized import DecodedPose, NormalizedPoses
from ecs_anim.core.skeleton import N_JOINTS
from ecs_anim.runtime.kernels import over_chunks
from ecs_anim.runtime.kernels.decode import (
    DecodedArrays,
    PoseArrays,
    decode_rows,
    decoded_arrays,
    decoded_pose,
    empty_decoded,
    pose_arrays,
    spine_scratch,
)
from ecs_anim.runtime.kernels.vec import (
    F64,
    Quat,
    Vec3,
    copy_row,
    cross,
    dot,
    jit,
    load3,
    load4,
    quat_mul,
    store3,
    store4,
)
from ecs_anim.solver.goals import TickGoals
from ecs_anim.solver.joint_speed import (
    DIRECTION_GROUP,
    DIRECTIONS_AT,
    FRAME_GROUP,
    LEG_JOINTS,
    N_GROUPS,
    N_VALUES,
    SHIFT_GROUP,
    SHIFTS_AT,
    MotionBefore,
)

B8 = NDArray[np.bool_]
I64 = NDArray[np.int64]
_N_FRAMES, _N_DIRECTIONS, _N_SHIFTS = 6, 5, 13
#: (N_JOINTS,) the leg each joint is below the hip of (0 left, 1 right; -1: none).
LEG_OF_JOINT = np.full(N_JOINTS, -1, np.int64)
for _side, _joints in enumerate(LEG_JOINTS):
    LEG_OF_JOINT[list(_joints)] = _side


@jit(inline="always")
def conj(q: Quat) -> Quat:
    return (-q[0], -q[1], -q[2], q[3])


@jit()
def rotvec_of(q: Quat) -> Vec3:
    """Mirrors ``_rotvec_of``: the rotation vector (rad) of a unit quaternion."""
    if q[3] < 0.0:
        q = (-q[0], -q[1], -q[2], -q[3])
    s = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2])
    per = 2.0 if s < 1e-12 else 2.0 * math.atan2(s, q[3]) / s
    return (q[0] * per, q[1] * per, q[2] * per)


@jit()
def quat_of(r: Vec3) -> Quat:
    """Mirrors ``_quat_of``: the unit quaternion of a rotation vector (rad)."""
    angle = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    per = 0.5 if angle < 1e-12 else math.sin(0.5 * angle) / angle
    return (r[0] * per, r[1] * per, r[2] * per, math.cos(0.5 * angle))


@jit()
def quat_between(a: Vec3, b: Vec3) -> Quat:
    """Mirrors ``_quat_between``: the smallest turn taking unit ``a`` onto unit ``b``."""
    c = dot(a, b)
    if c < -1.0 + 1e-9:
        helper = (1.0, 0.0, 0.0) if abs(a[0]) < 0.9 else (0.0, 1.0, 0.0)
        k = cross(a, helper)
        q = (k[0], k[1], k[2], 0.0)
    else:
        k = cross(a, b)
        q = (k[0], k[1], k[2], 1.0 + c)
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


@jit()
def rotate(q: Quat, v: Vec3) -> Vec3:
    """Mirrors ``_rotate``: ``v`` turned by the unit quaternion ``q``."""
    u = (q[0], q[1], q[2])
    c = cross(u, v)
    t = (2.0 * c[0], 2.0 * c[1], 2.0 * c[2])
    ut = cross(u, t)
    return (v[0] + q[3] * t[0] + ut[0], v[1] + q[3] * t[1] + ut[1], v[2] + q[3] * t[2] + ut[2])


@jit(inline="always")
def _frame(p: PoseArrays, c: int, k: int) -> Quat:
    """Frame ``k`` of row ``c`` (legs, arms, thorax, head)."""
    if k < 2:
        return load4(p.leg_frame[c, k])
    if k < 4:
        return load4(p.arm_frame[c, k - 2])
    if k == 4:
        return load4(p.thorax[c])
    return load4(p.head[c])


@jit(inline="always")
def _set_frame(p: PoseArrays, c: int, k: int, q: Quat) -> None:
    if k < 2:
        store4(p.leg_frame[c, k], q)
    elif k < 4:
        store4(p.arm_frame[c, k - 2], q)
    elif k == 4:
        store4(p.thorax[c], q)
    else:
        store4(p.head[c], q)


@jit(inline="always")
def _direction(p: PoseArrays, c: int, k: int) -> Vec3:
    """Direction ``k`` of row ``c`` (feet, hands, neck)."""
    if k < 2:
        return load3(p.foot_dir[c, k])
    if k < 4:
        return load3(p.hand_dir[c, k - 2])
    return load3(p.neck_dir[c])


@jit(inline="always")
def _set_direction(p: PoseArrays, c: int, k: int, v: Vec3) -> None:
    if k < 2:
        store3(p.foot_dir[c, k], v)
    elif k < 4:
        store3(p.hand_dir[c, k - 2], v)
    else:
        store3(p.neck_dir[c], v)


@jit(inline="always")
def _shift(p: PoseArrays, c: int, j: int) -> float:
    """Shifted value ``j`` of row ``c`` (leg fractions, arm fractions, spine coordinates)."""
    if j < 2:
        return float(p.leg_fraction[c, j])
    if j < 4:
        return float(p.arm_fraction[c, j - 2])
    return float(p.spine_points[c, (j - 4) // 3, (j - 4) % 3])


@jit(inline="always")
def _set_shift(p: PoseArrays, c: int, j: int, value: float) -> None:
    if j < 2:
        p.leg_fraction[c, j] = value
    elif j < 4:
        p.arm_fraction[c, j - 2] = value
    else:
        p.spine_points[c, (j - 4) // 3, (j - 4) % 3] = value


@jit(inline="always")
def _shift_group(j: int) -> int:
    """The index into the reference's ``SHIFTS`` of shifted value ``j``."""
    return j if j < 4 else 4 + (j - 4) // 3


@jit(inline="always")
def pack_row(pose: PoseArrays, c: int, out: F64) -> None:
    """Row ``c`` of ``pose`` packed into row ``c`` of ``out`` (n, N_VALUES), as
    :func:`ecs_anim.solver.joint_speed.pack`."""
    for k in range(_N_FRAMES):
        store4(out[c, 4 * k:4 * k + 4], _frame(pose, c, k))
    for k in range(_N_DIRECTIONS):
        store3(out[c, DIRECTIONS_AT + 3 * k:DIRECTIONS_AT + 3 * k + 3], _direction(pose, c, k))
    for j in range(_N_SHIFTS):
        out[c, SHIFTS_AT + j] = _shift(pose, c, j)


@jit(nogil=True)
def pack_rows(lo: int, hi: int, rows: I64, pose: PoseArrays, out: F64) -> None:
    """Mirrors :func:`ecs_anim.solver.joint_speed.pack` for the rows ``rows[lo:hi]`` of ``pose``
    into the same rows of ``out`` (n, N_VALUES)."""
    for i in range(lo, hi):
        pack_row(pose, rows[i], out)


@jit(inline="always")
def _frame_turn(a: Quat, b: Quat) -> Vec3:
    """The rotation vector (rad) from quaternion ``a`` to ``b``."""
    return rotvec_of(quat_mul(b, conj(a)))


@jit(inline="always")
def _scaled(t: Vec3, share: float) -> Quat:
    """The quaternion of ``share`` of the turn ``t`` (a rotation vector, rad)."""
    return quat_of((t[0] * share, t[1] * share, t[2] * share))


@jit(inline="always")
def _limit_row(pose: PoseArrays, p: int, c: int, clip_now: F64, clip_before: F64,
               pose_before: F64, planted: B8, share: float, frame_group: I64,
               direction_group: I64, shift_group: I64, need: F64, held: B8) -> None:
    """Row ``p`` of ``pose`` limited in place by the row ``c`` of the other arrays (the share
    ``share``); ``held[c]`` whether anything was held back, ``need[c]`` scratch."""
    first = False
    for i in range(N_VALUES):
        first = first or pose_before[c, i] != 0.0
    held[c] = False
    for g in range(N_GROUPS):
        need[c, g] = min(share, 1.0) if first else 1.0
    for s in range(2):  # the legs' groups are 0 and 1
        if planted[c, s]:
            need[c, s] = 1.0
    for g in range(N_GROUPS):
        held[c] = held[c] or need[c, g] < 1.0
    if not held[c]:
        return
    for k in range(_N_FRAMES):
        part = need[c, frame_group[k]]
        if part < 1.0:
            at = 4 * k
            now_clip = load4(clip_now[c, at:at + 4])
            was = quat_mul(load4(pose_before[c, at:at + 4]), conj(load4(clip_before[c, at:at + 4])))
            now = quat_mul(_frame(pose, p, k), conj(now_clip))
            turn = _scaled(_frame_turn(was, now), part)
            _set_frame(pose, p, k, quat_mul(quat_mul(turn, was), now_clip))
    for k in range(_N_DIRECTIONS):
        part = need[c, direction_group[k]]
        if part < 1.0:
            at = DIRECTIONS_AT + 3 * k
            now_clip3 = load3(clip_now[c, at:at + 3])
            was = quat_between(load3(clip_before[c, at:at + 3]), load3(pose_before[c, at:at + 3]))
            now = quat_between(now_clip3, _direction(pose, p, k))
            turn = _scaled(_frame_turn(was, now), part)
            _set_direction(pose, p, k, rotate(quat_mul(turn, was), now_clip3))
    for j in range(_N_SHIFTS):
        part = need[c, shift_group[_shift_group(j)]]
        if part < 1.0:
            was_j = pose_before[c, SHIFTS_AT + j] - clip_before[c, SHIFTS_AT + j]
            now_j = _shift(pose, p, j) - clip_now[c, SHIFTS_AT + j]
            _set_shift(pose, p, j, clip_now[c, SHIFTS_AT + j] + was_j + part * (now_j - was_j))


@jit(nogil=True)
def limit_rows(lo: int, hi: int, pose: PoseArrays, clip_now: F64, clip_before: F64,
               pose_before: F64, planted: B8, share: F64, frame_group: I64,
               direction_group: I64, shift_group: I64, need: F64, held: B8) -> None:
    """Mirrors :func:`ecs_anim.solver.joint_speed.limit_motion` over rows ``lo..hi-1`` of
    ``pose`` (limited in place); ``held`` (r,) whether anything was held back; ``need``
    (r, N_GROUPS) scratch: each group's share of its way."""
    for c in range(lo, hi):
        _limit_row(pose, c, c, clip_now, clip_before, pose_before, planted, share[c],
                   frame_group, direction_group, shift_group, need, held)


@jit(inline="always")
def _share(c: int, pose_positions: F64, clip_positions: F64, pose_positions_before: F64,
           clip_positions_before: F64, planted: B8, max_step_m: float, goal_step_m: float,
           leg_of_joint: I64) -> float:
    """Row ``c``'s share (see :func:`share_rows`). The pelvis itself (joint 0) is left out: its
    change from itself is 0 (or NaN), which never lowers the share; the four pelvises are read
    once (about 9 % off the pass)."""
    share = 1.0
    pose0, clip0 = load3(pose_positions[c, 0]), load3(clip_positions[c, 0])
    pose0_before = load3(pose_positions_before[c, 0])
    clip0_before = load3(clip_positions_before[c, 0])
    for j in range(1, N_JOINTS):
        side = leg_of_joint[j]
        if side >= 0 and planted[c, side]:
            continue
        cc = 0.0
        dd = 0.0
        cd = 0.0
        for i in range(3):
            clip = clip_positions[c, j, i] - clip0[i]
            clip_before = clip_positions_before[c, j, i] - clip0_before[i]
            pose = pose_positions[c, j, i] - pose0[i]
            pose_before = pose_positions_before[c, j, i] - pose0_before[i]
            step = clip - clip_before
            change = (pose - clip) - (pose_before - clip_before)
            cc += step * step
            dd += change * change
            cd += step * change
        if dd > 0.0:
            allowed = math.sqrt(cc) + (max_step_m + goal_step_m)
            room = allowed * allowed - cc
            share = min(share, (-cd + math.sqrt(cd * cd + dd * room)) / max(dd, 1e-300))
    return share


@jit(nogil=True)
def share_rows(lo: int, hi: int, pose_positions: F64, clip_positions: F64,
               pose_positions_before: F64, clip_positions_before: F64, planted: B8,
               max_step_m: float, goal_steps_m: F64, leg_of_joint: I64, out: F64) -> None:
    """Mirrors :func:`ecs_anim.solver.joint_speed.step_shares` over rows ``lo..hi-1`` into
    ``out`` (r,); each joint measured from its pelvis here (the same subtraction as
    ``from_pelvis``, so the same bits), not in arrays of their own."""
    for c in range(lo, hi):
        out[c] = _share(c, pose_positions, clip_positions, pose_positions_before,
                        clip_positions_before, planted, max_step_m, goal_steps_m[c],
                        leg_of_joint)


@jit(inline="always")
def _copy_pose(dst: PoseArrays, i: int, src: PoseArrays, c: int) -> None:
    """``dst``'s row ``i`` = ``src``'s row ``c``, every field."""
    dst.root_heading[i] = src.root_heading[c]
    copy_row(dst.root_position, i, src.root_position, c)
    copy_row(dst.pelvis_local, i, src.pelvis_local, c)
    copy_row(dst.hip_dir, i, src.hip_dir, c)
    copy_row(dst.leg_frame, i, src.leg_frame, c)
    copy_row(dst.leg_fraction, i, src.leg_fraction, c)
    copy_row(dst.foot_dir, i, src.foot_dir, c)
    copy_row(dst.spine_points, i, src.spine_points, c)
    copy_row(dst.thorax, i, src.thorax, c)
    copy_row(dst.neck_dir, i, src.neck_dir, c)
    copy_row(dst.head, i, src.head, c)
    copy_row(dst.head_top_dir, i, src.head_top_dir, c)
    copy_row(dst.clavicle_dir, i, src.clavicle_dir, c)
    copy_row(dst.arm_frame, i, src.arm_frame, c)
    copy_row(dst.arm_fraction, i, src.arm_fraction, c)
    copy_row(dst.hand_dir, i, src.hand_dir, c)
    copy_row(dst.stretch, i, src.stretch, c)


@jit(nogil=True)
def again_rows(lo: int, hi: int, rows: I64, limited: PoseArrays, positions: F64,
               clip_positions: F64, pose_positions_before: F64, clip_positions_before: F64,
               planted: B8, max_step_m: float, goal_steps_m: F64, leg_of_joint: I64,
               clip_now: F64, clip_before: F64, pose_before: F64, frame_group: I64,
               direction_group: I64, shift_group: I64, need: F64, held: B8,
               part: PoseArrays) -> None:
    """Mirrors the share and the limit of :func:`ecs_anim.solver.joint_speed.limit_again` for
    ``i`` in ``lo..hi-1``: row ``rows[i]`` of ``limited`` (its joints ``positions``, that row
    decoded) into row ``i`` of ``part``, limited by its share once more (the other arrays'
    row ``rows[i]``, as :func:`share_rows` and :func:`limit_rows` read theirs)."""
    for i in range(lo, hi):
        c = rows[i]
        share = _share(c, positions, clip_positions, pose_positions_before,
                       clip_positions_before, planted, max_step_m, goal_steps_m[c], leg_of_joint)
        _copy_pose(part, i, limited, c)
        _limit_row(part, i, c, clip_now, clip_before, pose_before, planted, share, frame_group,
                   direction_group, shift_group, need, held)


@jit(nogil=True)
def put_rows(lo: int, hi: int, rows: I64, part: PoseArrays, part_decoded: DecodedArrays,
             pose: PoseArrays, decoded: DecodedArrays) -> None:
    """Mirrors :func:`ecs_anim.solver.joint_speed.put_back`: row ``i`` of ``part`` and
    ``part_decoded`` into row ``rows[i]`` of ``pose`` and ``decoded``, ``i`` in ``lo..hi-1``."""
    for i in range(lo, hi):
        c = rows[i]
        _copy_pose(pose, c, part, i)
        copy_row(decoded.positions, c, part_decoded.positions, i)
        copy_row(decoded.pelvis2world, c, part_decoded.pelvis2world, i)
        copy_row(decoded.thorax2world, c, part_decoded.thorax2world, i)
        copy_row(decoded.head2world, c, part_decoded.head2world, i)
        copy_row(decoded.leg2world, c, part_decoded.leg2world, i)
        copy_row(decoded.arm2world, c, part_decoded.arm2world, i)


def step_shares(pose_positions: F64, clip_positions: F64, pose_positions_before: F64,
                clip_positions_before: F64, planted: B8, max_step_m: float, goal_steps_m: F64
                ) -> F64:
    """Compiled :func:`ecs_anim.solver.joint_speed.step_shares` (same arguments and result)."""
    r = pose_positions.shape[0]
    out = np.empty(r)
    positions = [np.ascontiguousarray(a, dtype=np.float64) for a in (
        pose_positions, clip_positions, pose_positions_before, clip_positions_before)]
    over_chunks(share_rows, r, *positions, np.ascontiguousarray(planted, dtype=np.bool_),
                float(max_step_m), np.ascontiguousarray(goal_steps_m, dtype=np.float64),
                LEG_OF_JOINT, out)
    return out


def pack(poses: NormalizedPoses) -> F64:
    """Compiled :func:`ecs_anim.solver.joint_speed.pack` (same argument and result)."""
    r = poses.root_heading.shape[0]
    out = np.empty((r, N_VALUES))
    over_chunks(pack_rows, r, np.arange(r, dtype=np.int64), pose_arrays(poses), out)
    return out


def pack_into(poses: NormalizedPoses, rows: I64, out: F64) -> None:
    """``out[rows] = pack(poses)[rows]`` in place (``out`` (n, N_VALUES), C-contiguous)."""
    over_chunks(pack_rows, rows.size, np.ascontiguousarray(rows, dtype=np.int64),
                pose_arrays(poses), out)


def limit_motion(poses: NormalizedPoses, clip_now: F64, clip_before: F64, pose_before: F64,
                 planted: B8, share: F64) -> tuple[NormalizedPoses, B8]:
    """Compiled :func:`ecs_anim.solver.joint_speed.limit_motion` (same arguments and results),
    except that ``poses`` is limited in place and returned."""
    r = poses.root_heading.shape[0]
    held, need = np.empty(r, bool), np.empty((r, N_GROUPS))
    floats = [np.ascontiguousarray(a, dtype=np.float64)
              for a in (clip_now, clip_before, pose_before)]
    over_chunks(limit_rows, r, pose_arrays(poses), *floats,
                np.ascontiguousarray(planted, dtype=np.bool_),
                np.ascontiguousarray(share, dtype=np.float64), FRAME_GROUP,
                DIRECTION_GROUP, SHIFT_GROUP, need, held)
    return poses, held


def limit_again(limited: NormalizedPoses, rows: I64, before: MotionBefore, lengths: F64,
                planted: B8, max_step_m: float) -> tuple[NormalizedPoses, DecodedPose]:
    """Compiled :func:`ecs_anim.solver.joint_speed.limit_again` (same arguments and results):
    the held rows of ``limited`` decoded where they are (:func:`~.decode.decode_rows`), taken
    out, shared and limited in one pass (:func:`again_rows`), decoded again."""
    n, r = limited.root_heading.shape[0], rows.size
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    pose = pose_arrays(limited)
    lengths = np.ascontiguousarray(lengths, dtype=np.float64)
    decoded = empty_decoded(n)  # (only the rows held back are written)
    over_chunks(decode_rows, r, rows, pose, lengths, decoded, spine_scratch(r))
    part = PoseArrays(*(np.empty((r, *getattr(pose, name).shape[1:]))
                        for name in PoseArrays._fields))
    floats = [np.ascontiguousarray(a, dtype=np.float64) for a in (
        before.clip_positions, before.pose_positions_before, before.clip_positions_before)]
    more = [np.ascontiguousarray(a, dtype=np.float64) for a in (
        before.clip_now, before.clip_before, before.pose_before)]
    over_chunks(again_rows, r, rows, pose, decoded.positions, *floats,
                np.ascontiguousarray(planted, dtype=np.bool_), float(max_step_m),
                np.ascontiguousarray(before.goal_steps_m, dtype=np.float64), LEG_OF_JOINT,
                *more, FRAME_GROUP, DIRECTION_GROUP, SHIFT_GROUP, np.empty((n, N_GROUPS)),
                np.empty(n, np.bool_), part)
    part_decoded = empty_decoded(r)
    over_chunks(decode_rows, r, np.arange(r, dtype=np.int64), part, lengths[rows], part_decoded,
                spine_scratch(r))
    return (NormalizedPoses(**dict(zip(PoseArrays._fields, part, strict=True))),
            decoded_pose(part_decoded))


def put_back(poses: NormalizedPoses, decoded: DecodedPose, rows: I64, part: NormalizedPoses,
             part_decoded: DecodedPose) -> None:
    """Compiled :func:`ecs_anim.solver.joint_speed.put_back` (same arguments, in place)."""
    over_chunks(put_rows, rows.size, np.ascontiguousarray(rows, dtype=np.int64), pose_arrays(part),
                decoded_arrays(part_decoded), pose_arrays(poses), decoded_arrays(decoded))


#: What :func:`ecs_anim.solver.joint_speed.goal_steps` makes of a step that is not finite
#: (``np.nan_to_num``: NaN 0, an overflow the largest float).
_LARGEST = float(np.finfo(np.float64).max)


@jit(nogil=True)
def goal_steps_rows(table_index: I64, owner: I64, orientation: B8, goal: F64, weight: F64,
                    weight_before: F64, last_goals: F64, steps: F64) -> None:
    """Mirrors :func:`ecs_anim.solver.joint_speed.goal_steps` over the k goals (``table_index``,
    ``owner``, ``orientation``, ``goal``, ``weight`` as in ``TickGoals``): each character's
    step into ``steps`` (r,), zeros on entry; ``last_goals`` (m, 3) read, then made this tick's."""
    for j in range(table_index.shape[0]):
        i = table_index[j]
        if i < 0 or not weight[j] >= 1.0:
            continue
        c = owner[j]
        if weight_before[i] <= 0.0:  # switched on at once
            steps[c] = math.inf
        elif not orientation[j]:
            dx = goal[j, 0] - last_goals[i, 0]
            dy = goal[j, 1] - last_goals[i, 1]
            dz = goal[j, 2] - last_goals[i, 2]
            moved = math.sqrt(dx * dx + dy * dy + dz * dz)
            if math.isnan(moved):
                moved = 0.0
            elif math.isinf(moved):
                moved = _LARGEST
            steps[c] = max(steps[c], moved)
    last_goals[:] = math.nan
    for j in range(table_index.shape[0]):
        i = table_index[j]
        if i >= 0 and weight[j] >= 1.0 and not orientation[j]:
            last_goals[i, 0], last_goals[i, 1], last_goals[i, 2] = (goal[j, 0], goal[j, 1],
                                                                    goal[j, 2])


def goal_steps(goals: TickGoals, last_goals: F64, weight_before: F64) -> F64:
    """Compiled :func:`ecs_anim.solver.joint_speed.goal_steps` (same arguments and result;
    ``last_goals`` C-contiguous, updated in place)."""
    steps = np.zeros(goals.rows.size)
    goal_steps_rows(np.ascontiguousarray(goals.table_index, dtype=np.int64),
                    np.ascontiguousarray(goals.owner, dtype=np.int64),
                    np.ascontiguousarray(goals.orientation, dtype=np.bool_),
                    np.ascontiguousarray(goals.goal, dtype=np.float64),
                    np.ascontiguousarray(goals.weight, dtype=np.float64),
                    np.ascontiguousarray(weight_before, dtype=np.float64), last_goals, steps)
    return steps


@jit(nogil=True)
def differing_rows(lo: int, hi: int, values: F64, other: F64, out: B8) -> None:
    """Mirrors :func:`ecs_anim.solver.joint_speed.rows_differ` over rows ``lo..hi-1`` into
    ``out`` (r,), each row read only up to its first difference."""
    for c in range(lo, hi):
        out[c] = False
        for i in range(values.shape[1]):
            if values[c, i] != other[c, i]:
                out[c] = True
                break


def rows_differ(values: F64, other: F64) -> B8:
    """Compiled :func:`ecs_anim.solver.joint_speed.rows_differ` (same arguments and result)."""
    out = np.empty(values.shape[0], np.bool_)
    over_chunks(differing_rows, values.shape[0], np.ascontiguousarray(values, dtype=np.float64),
                np.ascontiguousarray(other, dtype=np.float64), out)
    return out
