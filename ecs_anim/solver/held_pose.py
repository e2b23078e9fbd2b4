"""A character the frame budget solves only every few ticks keeps its last solve's correction in
between (:class:`HeldCorrections`), so its constraints stay about met instead of switching off.

When a character is solved, what the solve set is kept: the trunk's, arms' and head's values
as solved (the normalized pose's fields the solver sets: :data:`HELD_FIELDS`), and for the legs
and the root, the correction relative to the motion's pose of that tick: each leg's frame as the
turn from the motion's to the solved one (in the pelvis's frame), each foot's direction as the
smallest turn, each leg's fraction as a difference, the root's move in the heading's frame (the
centre of mass's correction, so it turns with the character). On a tick it is not solved, the
trunk, arms and head get their solved values back (in the pelvis's frame) and the legs and the
root the correction put on the motion's: the legs go on stepping, a wrist held on a target
moves only with the pelvis for the few ticks until the next solve, and nothing pops when the
solve comes back. (Putting the correction on the upper body's motion too made a wrist the solve
put on a target 0.5 m off the motion's drift 4-5 mm a tick in an idle: the motion's small turns
of the trunk and the arm cancel at its own wrist, not at the solved one's.)

Numpy over the rows held (no loop per character): about a microsecond each.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.normalized import NormalizedPoses
from ecs_anim.core.rotations import normalize, quat_between, quat_conj, quat_mul, quat_rotate

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: The fields of the normalized pose the solver sets on the trunk, the arms and the head: held
#: as solved between two solves.
HELD_FIELDS = ("thorax", "spine_points", "head", "neck_dir", "arm_frame", "arm_fraction",
               "hand_dir")


def _to_heading(offset_xy: F64, heading: F64) -> F64:
    """(r, 2) horizontal world offsets turned by ``-heading`` (r,) rad: in the heading's frame."""
    c, s = np.cos(heading), np.sin(heading)
    return np.stack([c * offset_xy[:, 0] + s * offset_xy[:, 1],
                     -s * offset_xy[:, 0] + c * offset_xy[:, 1]], axis=1)



class HeldCorrections:
    """Each store row's last solve (n rows; ``known`` (n,): which rows have one): the held
    fields as solved (:data:`HELD_FIELDS`, each (n, ...)), each leg's turn (n, 2, 4) and foot's
    turn (n, 2, 4, quaternions), leg fraction's difference (n, 2), and the root's move (n, 3:
    horizontal in the heading's frame, vertical; leg lengths). Reset when the store's rows
    change."""

    def __init__(self) -> None:
        self.known: NDArray[np.bool_] = np.zeros(0, bool)
        self.held: dict[str, F64] = {}
        self.leg_turn: F64 = np.zeros((0, 2, 4))
        self.foot_turn: F64 = np.zeros((0, 2, 4))
        self.leg_fraction_change: F64 = np.zeros((0, 2))
        self.root_move: F64 = np.zeros((0, 3))
        self._version = -1

    def start_tick(self, poses: NormalizedPoses, version: int) -> None:
        """Forget every row's correction when the store's structure (``version``) or its row
        count (that of ``poses``, the store's) changed."""
        n = poses.root_heading.shape[0]
        if version != self._version or self.known.size != n:
            self._version = version
            self.known = np.zeros(n, bool)
            self.held = {name: np.zeros_like(getattr(poses, name)) for name in HELD_FIELDS}
            self.leg_turn = np.zeros((n, 2, 4))
            self.foot_turn = np.zeros((n, 2, 4))
            self.leg_fraction_change = np.zeros((n, 2))
            self.root_move = np.zeros((n, 3))

    def keep(self, rows: I64, motion: NormalizedPoses, solved: NormalizedPoses) -> None:
        """The solve of ``rows`` (r,): the motion's poses (r,) and the solved ones (r,)."""
        for name in HELD_FIELDS:
            self.held[name][rows] = getattr(solved, name)
        self.leg_turn[rows] = quat_mul(solved.leg_frame, quat_conj(motion.leg_frame))
        self.foot_turn[rows] = quat_between(motion.foot_dir, solved.foot_dir)
        self.leg_fraction_change[rows] = solved.leg_fraction - motion.leg_fraction
        move = solved.root_position - motion.root_position
        self.root_move[rows, :2] = _to_heading(move[:, :2], motion.root_heading)
        self.root_move[rows, 2] = move[:, 2]
        self.known[rows] = True

    def put_on(self, poses: NormalizedPoses, rows: I64) -> None:
        """Put the kept correction of ``rows`` (r,; each ``known``) on ``poses`` (n,: this
        tick's motion poses, changed in place)."""
        for name in HELD_FIELDS:
            getattr(poses, name)[rows] = self.held[name][rows]
        poses.leg_frame[rows] = normalize(quat_mul(self.leg_turn[rows], poses.leg_frame[rows]))
        poses.foot_dir[rows] = normalize(quat_rotate(self.foot_turn[rows], poses.foot_dir[rows]))
        poses.leg_fraction[rows] += self.leg_fraction_change[rows]
        move = self.root_move[rows]
        poses.root_position[rows, :2] += _to_heading(move[:, :2], -poses.root_heading[rows])
        poses.root_position[rows, 2] += move[:, 2]


__all__ = ["HELD_FIELDS", "HeldCorrections"]
