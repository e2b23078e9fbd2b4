"""Sampling normalized motions at any time, for many characters at once.

All clips live in one :class:`ClipBank` (their frames concatenated), so one call samples every
character whatever clip it plays: interpolation happens in normalized space (slerp for
orientations, normalized lerp for directions, lerp for fractions and normalized positions), and a
looping clip carries its root motion across loops (each loop starts where the previous one ended,
turned by the heading the clip gained).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.ground_adapt import sole_roll
from ecs_anim.core.normalized import DIRECTION_FIELDS, QUATERNION_FIELDS, NormalizedPoses
from ecs_anim.core.rotations import normalize, slerp
from ecs_anim.motion.clip import NormalizedMotion

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


def wrap_angle(angle: F64) -> F64:
    return (angle + np.pi) % (2 * np.pi) - np.pi


def rotate_xy(xy: F64, angle: F64) -> F64:
    """Rotate points ``xy`` (..., 2) anticlockwise by ``angle`` (...) radians."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * xy[..., 0] - s * xy[..., 1], s * xy[..., 0] + c * xy[..., 1]], axis=-1)


@dataclass
class ClipBank:
    """Every clip's frames, concatenated.

    poses : NormalizedPoses with leading shape (total_frames,).
    start : (n_clips,) first frame of each clip in ``poses``; n_frames : (n_clips,) frame count.
    fps : (n_clips,).
    loop_yaw : (n_clips,) heading gained over one loop (radians).
    loop_shift : (n_clips, 2) root displacement over one loop, normalized units, expressed in the
        clip's first-frame position frame (world xy of the clip).
    names : clip names.
    contact_weight : (total_frames, 2) foot-contact activation per frame [left, right].
    capture_ground : (total_frames, 1) the ground each capture stood on, in its leg lengths
        (:attr:`~ecs_anim.motion.clip.NormalizedMotion.capture_ground`; 0 where not known).
    sole_roll : (total_frames, 2) the part of each foot the clip plants per frame (0 heel, 1
        ball, 0.5 both or not known: :func:`ecs_anim.core.ground_adapt.sole_roll`).
    source_ankle_height : (n_clips, 2) each source's ankle heights in its leg lengths.
    """

    poses: NormalizedPoses
    start: I64
    n_frames: I64
    fps: F64
    loop_yaw: F64
    loop_shift: F64
    names: list[str]
    contact_weight: F64
    source_ankle_height: F64
    sole_roll: F64
    capture_ground: F64

    @classmethod
    def from_motions(cls, motions: dict[str, NormalizedMotion]) -> ClipBank:
        names = list(motions)
        fields = {k: np.concatenate([getattr(motions[n].poses, k) for n in names])
                  for k in motions[names[0]].poses.arrays()}
        counts = np.array([motions[n].n_frames for n in names], dtype=np.int64)
        start = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
        yaw, shift = [], []
        for n in names:
            p = motions[n].poses
            if p.root_heading.shape[0] >= 2:
                # The frame after the last one, extrapolated, is where the next loop starts.
                h_next = p.root_heading[-1] + wrap_angle(p.root_heading[-1] - p.root_heading[-2])
                xy_next = 2 * p.root_position[-1, :2] - p.root_position[-2, :2]
            else:
                h_next, xy_next = p.root_heading[0], p.root_position[0, :2]
            yaw.append(wrap_angle(h_next - p.root_heading[0]))
            shift.append(xy_next - p.root_position[0, :2])
        # Foot-contact weights per frame, and each source's ankle height in leg lengths.
        weights = []
        for n in names:
            m = motions[n]
            t = np.arange(m.n_frames) / m.fps
            w = np.zeros((m.n_frames, 2))
            for c in m.constraints:
                if c.kind == "foot_contact":
                    side = 0 if c.segment.endswith("_l") else 1
                    w[:, side] = np.maximum(w[:, side], c.activation.weight(t, smooth=False))
            weights.append(w)
        rolls = [np.full((motions[n].n_frames, 2), 0.5) if motions[n].planted is None
                 else sole_roll(motions[n].planted_part("heel"), motions[n].planted_part("ball"))
                 for n in names]
        grounds = [motions[n].ground_under() for n in names]
        ankle = np.array([np.array([motions[n].source_morphology["ankle_height_l"],
                                    motions[n].source_morphology["ankle_height_r"]])
                          / motions[n].source_morphology.leg_length for n in names])
        return cls(NormalizedPoses(**fields), start, counts,
                   np.array([motions[n].fps for n in names], dtype=np.float64),
                   np.array(yaw), np.array(shift), names, np.concatenate(weights), ankle,
                   np.concatenate(rolls), np.concatenate(grounds)[:, None])

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"unknown clip {name!r}; loaded clips: {', '.join(self.names)}") from None

    def duration_s(self, clip: I64) -> F64:
        """Loop period of each clip: n_frames / fps (the last frame leads back to the first)."""
        return self.n_frames[clip] / self.fps[clip]


def loop_transform(bank: ClipBank, clip: I64, loops: F64) -> tuple[F64, F64]:
    """The rigid motion of the root after ``loops`` whole loops, in closed form (any count).

    After k loops a root at ``p`` (xy, normalized) is at ``p0 + moved + R(angle) (p - p0)``,
    with ``angle = k·yaw`` and ``moved = s · Σ_{i<k} R(i·yaw)`` (``s`` the per-loop shift,
    ``p0`` the clip's first root position). Returns (angle (n,), moved (n, 2)).
    """
    yaw = bank.loop_yaw[clip]
    shift = bank.loop_shift[clip, 0] + 1j * bank.loop_shift[clip, 1]
    step = np.exp(1j * yaw)
    small = np.abs(yaw) < 1e-9
    # Σ_{i<k} e^{i·yaw·i}: geometric series, k where yaw is ~0.
    series = np.where(small, loops, (1 - step**loops) / np.where(small, 1.0, 1 - step))
    moved = shift * series
    return loops * yaw, np.stack([moved.real, moved.imag], axis=-1)


def _root_frame(bank: ClipBank, clip: I64, local: I64, loops: F64) -> tuple[F64, F64]:
    """The root's ground position (n, 2) (normalized) and heading (n,) at stored frames
    ``local`` of ``clip`` after ``loops`` whole loops of root motion."""
    rows = bank.start[clip] + local
    angle, moved = loop_transform(bank, clip, loops)
    p0 = bank.poses.root_position[bank.start[clip], :2]
    rel = bank.poses.root_position[rows, :2] - p0
    return p0 + moved + rotate_xy(rel, angle), bank.poses.root_heading[rows] + angle


def _frame(bank: ClipBank, clip: I64, local: I64, loops: F64) -> NormalizedPoses:
    """Stored frames ``local`` of ``clip`` after ``loops`` whole loops of root motion."""
    out = bank.poses.take(bank.start[clip] + local)
    out.root_position = out.root_position.copy()
    out.root_position[:, :2], out.root_heading = _root_frame(bank, clip, local, loops)
    return out


def blend(a: NormalizedPoses, b: NormalizedPoses, w: F64) -> NormalizedPoses:
    """Interpolate two batches of poses with weights ``w`` (n,) in [0, 1] (0 -> a, 1 -> b)."""
    out: dict[str, F64] = {}
    for name, va in a.arrays().items():
        vb = getattr(b, name)
        ww = w.reshape(w.shape + (1,) * (va.ndim - 1))
        if name in QUATERNION_FIELDS:
            out[name] = slerp(va, vb, np.broadcast_to(ww[..., 0], va.shape[:-1]))
        elif name in DIRECTION_FIELDS:
            out[name] = normalize((1 - ww) * va + ww * vb)
        elif name == "root_heading":
            out[name] = va + w * wrap_angle(vb - va)
        else:
            out[name] = (1 - ww) * va + ww * vb
    return NormalizedPoses(**out)


def frame_position(bank: ClipBank, clip: I64, time_s: F64,
                   loop: NDArray[np.bool_]) -> tuple[I64, I64, F64, F64, NDArray[np.bool_]]:
    """Where ``time_s`` falls in each clip: (frame i0, frame i1, weight of i1, whole loops done,
    whether i1 wraps into the next loop). Looping clips wrap; others clamp to their ends."""
    n_frames = bank.n_frames[clip]
    f = np.asarray(time_s, dtype=np.float64) * bank.fps[clip]
    loops = np.where(loop, np.floor(f / n_frames), 0.0)
    local = np.where(loop, f - loops * n_frames, np.clip(f, 0.0, n_frames - 1.0))
    i0 = np.minimum(np.floor(local).astype(np.int64), n_frames - 1)
    wraps = loop & (i0 + 1 >= n_frames)
    i1 = np.where(wraps, 0, np.minimum(i0 + 1, n_frames - 1))
    return i0, i1, local - i0, loops, wraps


def sample_table(bank: ClipBank, table: F64, clip: I64, time_s: F64,
                 loop: NDArray[np.bool_]) -> F64:
    """Linear interpolation of a per-frame table aligned with the bank (total_frames, ...)."""
    i0, i1, w, _, _ = frame_position(bank, clip, time_s, loop)
    a, b = table[bank.start[clip] + i0], table[bank.start[clip] + i1]
    sampled: F64 = a + w.reshape(w.shape + (1,) * (a.ndim - 1)) * (b - a)
    return sampled


def sample(bank: ClipBank, clip: I64, time_s: F64, loop: NDArray[np.bool_]) -> NormalizedPoses:
    """Poses of ``clip`` (n,) at ``time_s`` (n,) seconds from each clip's start.

    Looping clips wrap with root motion carried over; others hold their first/last pose outside
    their duration. Returns NormalizedPoses with leading shape (n,).
    """
    i0, i1, w, loops, wraps = frame_position(bank, clip, time_s, loop)
    a = _frame(bank, clip, i0, loops)
    b = _frame(bank, clip, i1, loops + wraps)
    return blend(a, b, w)


def sample_root(bank: ClipBank, clip: I64, time_s: F64,
                loop: NDArray[np.bool_]) -> tuple[F64, F64]:
    """The root's ground position (n, 2) (normalized units) and heading (n,) of what
    :func:`sample` returns, bit for bit, without the rest of the pose: starting a clip places
    it by its root alone, and blending a whole pose (every slerp) cost most of a trigger's
    tick."""
    i0, i1, w, loops, wraps = frame_position(bank, clip, time_s, loop)
    n = clip.shape[0]
    # Both frames of every row in one pass (elementwise: each row's numbers are its own).
    xy, heading = _root_frame(bank, np.concatenate([clip, clip]), np.concatenate([i0, i1]),
                              np.concatenate([loops, loops + wraps]))
    ww = w[:, None]
    return (1 - ww) * xy[:n] + ww * xy[n:], heading[:n] + w * wrap_angle(heading[n:] - heading[:n])
