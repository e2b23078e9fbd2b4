"""A character the frame budget solves only every few ticks keeps its last solve's correction in
between (:class:`HeldCorrections`), so its constraints stay about met instead of switching off.

When a character is solved, its solved values (those of
:func:`ecs_anim.solver.joint_speed.pack`) and the motion's of that tick are kept, with the
root's move in the heading's frame (the centre of mass's correction, so it turns with the
character). On a tick it is not solved: the root gets the same move from the motion's root, the
legs the solve's correction put on the motion's legs (they go on stepping), and the trunk, arms
and head their solved values, in the pelvis's frame (:func:`corrected_values`): a wrist held on
a target moves only with the pelvis for the few ticks until the next solve, and nothing pops
when the solve comes back.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.body_points import LEG_L, LEG_R
from ecs_anim.core.normalized import NormalizedPoses
from ecs_anim.solver.joint_speed import (
    DIRECTIONS,
    DIRECTIONS_AT,
    FRAMES,
    N_VALUES,
    SHIFT_START,
    SHIFTS,
    SHIFTS_AT,
    _conj,
    _quat_between,
    _quat_mul,
    _rotate,
    _set,
)

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

_LEGS = (LEG_L, LEG_R)
#: The legs' frames, directions and shifts (their columns in the packed values): these follow
#: the motion between two solves.
LEG_FRAMES = tuple(k for k, (*_, group) in enumerate(FRAMES) if group in _LEGS)
LEG_DIRECTIONS = tuple(k for k, (*_, group) in enumerate(DIRECTIONS) if group in _LEGS)
LEG_SHIFTS = tuple(SHIFTS_AT + int(SHIFT_START[k]) for k, (*_, width, group) in enumerate(SHIFTS)
                   if group in _LEGS and width == 1)


def _to_heading(offset_xy: F64, heading: F64) -> F64:
    """(r, 2) horizontal world offsets turned by ``-heading`` (r,) rad: in the heading's frame."""
    c, s = np.cos(heading), np.sin(heading)
    return np.stack([c * offset_xy[:, 0] + s * offset_xy[:, 1],
                     -s * offset_xy[:, 0] + c * offset_xy[:, 1]], axis=1)


def _from_heading(offset_xy: F64, heading: F64) -> F64:
    """(r, 2) offsets in the heading's frame turned back into the world's."""
    return _to_heading(offset_xy, -heading)


def corrected_values(clip_now: F64, clip_then: F64, pose_then: F64) -> F64:
    """(r, N_VALUES) the packed pose of characters between two solves: the legs' values are
    ``clip_now`` (the motion's this tick, so they go on stepping) with the correction that took
    ``clip_then`` to ``pose_then`` (the motion's and the solve's at the last solve) put on them:
    frames turned by the same turn, feet by the same smallest turn, fractions moved by the same
    difference; the rest of the body (trunk, arms, head) is held as solved, in the pelvis's
    frame. (Putting the correction on the upper body's motion too made a wrist the solve put on
    a target 0.5 m off the motion's drift 4-5 mm a tick in an idle: the motion's small turns
    of the trunk and the arm cancel at its own wrist, not at the solved one's.)"""
    out = pose_then.copy()
    for k in LEG_FRAMES:
        at = slice(4 * k, 4 * k + 4)
        turn = _quat_mul(pose_then[:, at], _conj(clip_then[:, at]))
        q = _quat_mul(turn, clip_now[:, at])
        out[:, at] = q / np.linalg.norm(q, axis=1, keepdims=True)
    for k in LEG_DIRECTIONS:
        at = slice(DIRECTIONS_AT + 3 * k, DIRECTIONS_AT + 3 * k + 3)
        v = _rotate(_quat_between(clip_then[:, at], pose_then[:, at]), clip_now[:, at])
        out[:, at] = v / np.linalg.norm(v, axis=1, keepdims=True)
    for at in LEG_SHIFTS:
        out[:, at] = clip_now[:, at] + pose_then[:, at] - clip_then[:, at]
    return out


def unpack_into(poses: NormalizedPoses, rows: I64, values: F64) -> None:
    """Write packed ``values`` (r, N_VALUES) into the rows ``rows`` (r,) of ``poses`` (the
    inverse of :func:`ecs_anim.solver.joint_speed.pack`)."""
    at = 0
    for name, index, _ in FRAMES:
        _set(poses, name, index, rows, values[:, at:at + 4])
        at += 4
    for name, index, _ in DIRECTIONS:
        _set(poses, name, index, rows, values[:, at:at + 3])
        at += 3
    for name, index, width, _ in SHIFTS:
        part = values[:, at:at + width]
        _set(poses, name, index, rows, part[:, 0] if width == 1 else part)
        at += width


class HeldCorrections:
    """Each store row's last solve (n rows): the motion's and the solved packed values
    (n, N_VALUES) and the root's move (n, 3: horizontal in the heading's frame, vertical), in
    leg lengths; ``known`` (n,) which rows have one. Reset when the store's rows change."""

    def __init__(self) -> None:
        self.clip_then: F64 = np.zeros((0, N_VALUES))
        self.pose_then: F64 = np.zeros((0, N_VALUES))
        self.root_move: F64 = np.zeros((0, 3))
        self.known: NDArray[np.bool_] = np.zeros(0, bool)
        self._version = -1

    def start_tick(self, version: int, n: int) -> None:
        """Forget every row's correction when the store's structure (``version``) or its row
        count ``n`` changed."""
        if version != self._version or self.known.size != n:
            self._version = version
            self.clip_then = np.zeros((n, N_VALUES))
            self.pose_then = np.zeros((n, N_VALUES))
            self.root_move = np.zeros((n, 3))
            self.known = np.zeros(n, bool)

    def keep(self, rows: I64, clip_values: F64, pose_values: F64, clip_root: F64,
             pose_root: F64, heading: F64) -> None:
        """The solve of ``rows`` (r,): the motion's and the solved packed values (r, N_VALUES),
        root positions (r, 3, leg lengths) and the motion's heading (r,, rad)."""
        self.clip_then[rows] = clip_values
        self.pose_then[rows] = pose_values
        move = pose_root - clip_root
        self.root_move[rows, :2] = _to_heading(move[:, :2], heading)
        self.root_move[rows, 2] = move[:, 2]
        self.known[rows] = True

    def put_on(self, poses: NormalizedPoses, rows: I64, clip_values: F64) -> None:
        """Put the kept correction of ``rows`` (r,; each ``known``) on ``poses`` (n,: this
        tick's motion poses, changed in place), ``clip_values`` (r, N_VALUES) their packed
        values."""
        unpack_into(poses, rows, corrected_values(clip_values, self.clip_then[rows],
                                                  self.pose_then[rows]))
        move = self.root_move[rows]
        poses.root_position[rows, :2] += _from_heading(move[:, :2], poses.root_heading[rows])
        poses.root_position[rows, 2] += move[:, 2]


__all__ = ["HeldCorrections", "corrected_values", "unpack_into"]
