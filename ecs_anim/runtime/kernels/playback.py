"""Compiled playback: each character's clip sampled, placed in the world and cross-faded.

Mirrors :func:`ecs_anim.motion.sampling.sample` (frames interpolated in normalized space, root motion
carried across loops), :func:`ecs_anim.motion.sampling.sample_table`, the placement of
``MotionPlayback._placed`` and :func:`ecs_anim.motion.sampling.blend`, writing the store's pose
arrays in place. The clip bank is read as a :class:`PlaybackBank`, made once per bank (the
slerps' angles between each frame and the next, and the loops' turns, computed there and not
every tick); the poses as :class:`~ecs_anim.runtime.kernels.decode.PoseArrays`.

:func:`sample_placed` samples each (clip, time, loop) the characters play once: characters
that play the same clip from the same time (a crowd started in step) share one sampled pose,
copied to each of them; only their placement is their own.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.normalized import TRAILING_SHAPES, NormalizedPoses
from ecs_anim.core.skeleton import N_LENGTHS
from ecs_anim.runtime.kernels import over_chunks
from ecs_anim.runtime.kernels.decode import PoseArrays, leg_length, pose_arrays
from ecs_anim.runtime.kernels.lanes import BLOCK, Column, at, slerp_angle, slerp_weights
from ecs_anim.runtime.kernels.solve_math import wrap_angle
from ecs_anim.runtime.kernels.vec import (
    F64,
    TINY,
    Vec3,
    jit,
    load3,
    nlerp,
    slerp,
    store3,
)

if TYPE_CHECKING:
    from ecs_anim.motion.sampling import ClipBank

I64 = NDArray[np.int64]
I32 = NDArray[np.int32]
B1 = NDArray[np.bool_]


@jit()
def rotate_xy(x: float, y: float, angle: float) -> tuple[float, float]:
    """Mirrors :func:`ecs_anim.motion.sampling.rotate_xy` for one point."""
    c, s = math.cos(angle), math.sin(angle)
    return c * x - s * y, s * x + c * y


# The blends are inlined into the row loop: fifteen a character.
@jit(inline="always")
def _blend_quat(a: F64, ra: int, b: F64, rb: int, w: float, out: F64, ro: int) -> None:
    """Row ``ro`` of the (n, 4) quaternions ``out``: rows ``ra`` of ``a``, ``rb`` of ``b``
    slerped (scalar indexing: no array views in the loop over characters)."""
    q = slerp((a[ra, 0], a[ra, 1], a[ra, 2], a[ra, 3]), (b[rb, 0], b[rb, 1], b[rb, 2], b[rb, 3]), w)
    out[ro, 0], out[ro, 1], out[ro, 2], out[ro, 3] = q[0], q[1], q[2], q[3]


@jit(inline="always")
def _blend_quat2(a: F64, ra: int, b: F64, rb: int, w: float, out: F64, ro: int) -> None:
    """As :func:`_blend_quat` for (n, 2, 4) quaternions [left, right]."""
    for s in range(2):
        q = slerp((a[ra, s, 0], a[ra, s, 1], a[ra, s, 2], a[ra, s, 3]),
                  (b[rb, s, 0], b[rb, s, 1], b[rb, s, 2], b[rb, s, 3]), w)
        out[ro, s, 0], out[ro, s, 1], out[ro, s, 2], out[ro, s, 3] = q[0], q[1], q[2], q[3]


@jit(inline="always")
def _blend_dir(a: F64, ra: int, b: F64, rb: int, w: float, out: F64, ro: int) -> None:
    """Row ``ro`` of the (n, 3) directions ``out``: normalized lerp of ``a[ra]``, ``b[rb]``."""
    v = nlerp((a[ra, 0], a[ra, 1], a[ra, 2]), (b[rb, 0], b[rb, 1], b[rb, 2]), w)
    out[ro, 0], out[ro, 1], out[ro, 2] = v[0], v[1], v[2]


@jit(inline="always")
def _blend_dir2(a: F64, ra: int, b: F64, rb: int, w: float, out: F64, ro: int) -> None:
    """As :func:`_blend_dir` for (n, 2, 3) directions [left, right]."""
    for s in range(2):
        v = nlerp((a[ra, s, 0], a[ra, s, 1], a[ra, s, 2]), (b[rb, s, 0], b[rb, s, 1], b[rb, s, 2]),
                  w)
        out[ro, s, 0], out[ro, s, 1], out[ro, s, 2] = v[0], v[1], v[2]


@jit(inline="always")
def _lerp(a: F64, ra: int, b: F64, rb: int, w: float, out: F64, ro: int) -> None:
    """Row ``ro`` of the (n, k) ``out``: ``(1 - w) a[ra] + w b[rb]``."""
    for k in range(a.shape[1]):
        out[ro, k] = (1 - w) * a[ra, k] + w * b[rb, k]


@jit(inline="always")
def _lerp3(a: F64, ra: int, b: F64, rb: int, w: float, out: F64, ro: int) -> None:
    """As :func:`_lerp` for (n, 3, 3) points."""
    for j in range(3):
        for k in range(3):
            out[ro, j, k] = (1 - w) * a[ra, j, k] + w * b[rb, j, k]


@jit(inline="always")
def blend_parts(a: PoseArrays, ra: int, b: PoseArrays, rb: int, w: float, out: PoseArrays,
                ro: int) -> None:
    """Mirrors :func:`ecs_anim.motion.sampling.blend` for every field but the root's: row ``ra`` of
    ``a`` and row ``rb`` of ``b`` with weight ``w`` of ``b``, into row ``ro`` of ``out`` (which
    may be ``b``'s row itself)."""
    _blend_quat(a.pelvis_local, ra, b.pelvis_local, rb, w, out.pelvis_local, ro)
    _blend_quat(a.thorax, ra, b.thorax, rb, w, out.thorax, ro)
    _blend_quat(a.head, ra, b.head, rb, w, out.head, ro)
    _blend_quat2(a.leg_frame, ra, b.leg_frame, rb, w, out.leg_frame, ro)
    _blend_quat2(a.arm_frame, ra, b.arm_frame, rb, w, out.arm_frame, ro)
    _blend_unslerped(a, ra, b, rb, w, out, ro)


@jit(inline="always")
def _blend_unslerped(a: PoseArrays, ra: int, b: PoseArrays, rb: int, w: float, out: PoseArrays,
                     ro: int) -> None:
    """The directions and lengths of :func:`blend_parts` (all but its quaternions)."""
    _blend_dir(a.neck_dir, ra, b.neck_dir, rb, w, out.neck_dir, ro)
    _blend_dir(a.head_top_dir, ra, b.head_top_dir, rb, w, out.head_top_dir, ro)
    _blend_dir2(a.hip_dir, ra, b.hip_dir, rb, w, out.hip_dir, ro)
    _blend_dir2(a.foot_dir, ra, b.foot_dir, rb, w, out.foot_dir, ro)
    _blend_dir2(a.clavicle_dir, ra, b.clavicle_dir, rb, w, out.clavicle_dir, ro)
    _blend_dir2(a.hand_dir, ra, b.hand_dir, rb, w, out.hand_dir, ro)
    _lerp(a.leg_fraction, ra, b.leg_fraction, rb, w, out.leg_fraction, ro)
    _lerp(a.arm_fraction, ra, b.arm_fraction, rb, w, out.arm_fraction, ro)
    _lerp3(a.spine_points, ra, b.spine_points, rb, w, out.spine_points, ro)
    _lerp(a.stretch, ra, b.stretch, rb, w, out.stretch, ro)


@jit()
def blend_root(pa: Vec3, ha: float, pb: Vec3, hb: float, w: float) -> tuple[Vec3, float]:
    """Mirrors :func:`ecs_anim.motion.sampling.blend` of ``root_position`` (lerp) and ``root_heading``
    (the shorter way round: numpy's modulo to the bit, without the C library's ``fmod`` where
    the difference is already within a turn, a fifth of :func:`sample_rows`' pass over its
    rows)."""
    p = ((1 - w) * pa[0] + w * pb[0], (1 - w) * pa[1] + w * pb[1], (1 - w) * pa[2] + w * pb[2])
    return p, ha + w * wrap_angle(hb - ha)


@jit()
def frame_position(n_frames: int, fps: float, time_s: float,
                   loop: bool) -> tuple[int, int, float, float, bool]:
    """Mirrors :func:`ecs_anim.motion.sampling.frame_position` for one character: (frame i0, frame i1,
    weight of i1, whole loops done, whether i1 wraps into the next loop)."""
    f = time_s * fps
    if loop:
        loops = math.floor(f / n_frames) * 1.0
        local = f - loops * n_frames
    else:
        loops = 0.0
        local = min(max(f, 0.0), n_frames - 1.0)
    i0 = min(math.floor(local), n_frames - 1)
    wraps = loop and i0 + 1 >= n_frames
    i1 = 0 if wraps else min(i0 + 1, n_frames - 1)
    return i0, i1, local - i0, loops, wraps


@jit()
def complex_power(re: float, im: float, exponent: float) -> tuple[float, float]:
    """``(re + i im) ** exponent`` as numpy computes it (``npy_cpow``): repeated squaring for a
    whole exponent under 100 in size, else ``exp(exponent * log(z))`` (the C library's
    ``cpow``, with ``log |z|`` from ``log1p`` as it computes it near the unit circle)."""
    n = int(exponent)
    if n == exponent and abs(n) < 100:
        rr, ri = 1.0, 0.0
        ar, ai = re, im
        m = abs(n)
        mask = 1
        while mask <= m:
            if m & mask:
                rr, ri = rr * ar - ri * ai, rr * ai + ri * ar
            mask <<= 1
            ar, ai = ar * ar - ai * ai, ar * ai + ai * ar
        if n < 0:
            z = 1.0 / complex(rr, ri)
            return z.real, z.imag
        return rr, ri
    log_abs = 0.5 * math.log1p((re - 1.0) * (re + 1.0) + im * im)
    a, b = exponent * log_abs, exponent * math.atan2(im, re)
    e = math.exp(a)
    return e * math.cos(b), e * math.sin(b)


@jit(inline="always")
def loop_transform(yaw: float, cos_yaw: float, sin_yaw: float, shift_x: float, shift_y: float,
                   loops: float) -> tuple[float, float, float]:
    """Mirrors ``ecs_anim.motion.sampling.loop_transform`` for one character: (angle, moved x, moved
    y) of the root after ``loops`` whole loops of a clip gaining ``yaw`` (of cosine ``cos_yaw``
    and sine ``sin_yaw``: :class:`PlaybackBank`) and ``shift`` each."""
    shift = complex(shift_x, shift_y)
    step = complex(cos_yaw, sin_yaw)
    if abs(yaw) < 1e-9:
        series = complex(loops, 0.0)
    else:
        pr, pi = complex_power(step.real, step.imag, loops)
        series = complex(1.0 - pr, -pi) / (1.0 - step)
    moved = shift * series
    return loops * yaw, moved.real, moved.imag


@jit(inline="always")
def _turned(x: float, y: float, cos_angle: float, sin_angle: float) -> tuple[float, float]:
    """:func:`rotate_xy` given the angle's cosine and sine (computed once for two points)."""
    return cos_angle * x - sin_angle * y, sin_angle * x + cos_angle * y


@jit(inline="always")
def _frame_root(bank: PoseArrays, first: int, frame: int, angle: float, cos_angle: float,
                sin_angle: float, moved_x: float, moved_y: float) -> tuple[Vec3, float]:
    """Root position and heading of bank row ``frame`` after the loop transform (mirrors
    ``ecs_anim.motion.sampling._frame``); ``first`` the clip's first row; the transform's
    ``angle`` given with its cosine and sine."""
    p0x, p0y = bank.root_position[first, 0], bank.root_position[first, 1]
    p = bank.root_position[frame]
    rx, ry = _turned(p[0] - p0x, p[1] - p0y, cos_angle, sin_angle)
    return (p0x + moved_x + rx, p0y + moved_y + ry, p[2]), bank.root_heading[frame] + angle


#: The quaternions a pose slerps, in the order of :class:`PlaybackBank`'s pair columns:
#: pelvis_local, thorax, head, leg_frame [left, right], arm_frame [left, right].
N_SLERPED = 7


class PlaybackBank(NamedTuple):
    """A clip bank as the playback kernels read it, made once per bank (:func:`playback_bank`).

    ``poses`` the bank's poses (total_frames,), contiguous; ``start``, ``n_frames`` (n_clips,)
    int64, ``fps``, ``loop_yaw`` (n_clips,) rad, ``loop_shift`` (n_clips, 2): as in
    :class:`ecs_anim.motion.sampling.ClipBank`; ``loop_cos``, ``loop_sin`` (n_clips,) the
    cosine and sine of ``loop_yaw``. ``next_row`` (total_frames,) int64: the bank row a frame
    is interpolated towards when its clip plays on (the next frame; a loop's first after its
    last); ``pair_cos`` (total_frames, N_SLERPED) the dot product of each slerped quaternion
    of a row with the same of its ``next_row`` and ``pair_angle`` their slerp's angle
    (:func:`.lanes.slerp_angle`). ``capture_ground`` (total_frames,) leg lengths,
    ``contact_weight``, ``sole_roll`` (total_frames, 2): the bank's per-frame tables."""

    poses: PoseArrays
    start: I64
    n_frames: I64
    fps: F64
    loop_yaw: F64
    loop_shift: F64
    loop_cos: F64
    loop_sin: F64
    next_row: I64
    pair_cos: F64
    pair_angle: F64
    capture_ground: F64
    contact_weight: F64
    sole_roll: F64


def playback_bank(bank: ClipBank) -> PlaybackBank:
    """``bank`` as :class:`PlaybackBank` (its arrays contiguous, its pairs' slerp angles and
    its loops' turns computed here, once)."""
    poses = PoseArrays(*(np.ascontiguousarray(a, np.float64) for a in pose_arrays(bank.poses)))
    start = np.ascontiguousarray(bank.start, np.int64)
    n_frames = np.ascontiguousarray(bank.n_frames, np.int64)
    total = int(poses.root_heading.shape[0])
    next_row = np.arange(1, total + 1, dtype=np.int64)
    next_row[start + n_frames - 1] = start
    pair_cos, pair_angle = np.empty((total, N_SLERPED)), np.empty((total, N_SLERPED))
    pair_tables(poses, next_row, pair_cos, pair_angle)
    loop_yaw = np.ascontiguousarray(bank.loop_yaw, np.float64)
    # np.cos and np.sin are math.cos and math.sin bit for bit (both call the C library's).
    return PlaybackBank(poses, start, n_frames, np.ascontiguousarray(bank.fps, np.float64),
                        loop_yaw, np.ascontiguousarray(bank.loop_shift, np.float64),
                        np.cos(loop_yaw), np.sin(loop_yaw), next_row, pair_cos, pair_angle,
                        np.ascontiguousarray(bank.capture_ground[:, 0], np.float64),
                        np.ascontiguousarray(bank.contact_weight, np.float64),
                        np.ascontiguousarray(bank.sole_roll, np.float64))


@jit(inline="always")
def _cos_half(a: F64, ra: int, rb: int) -> float:
    """Dot product of the quaternions ``a[ra]`` and ``a[rb]`` ((n, 4))."""
    cos_half: float = (a[ra, 0] * a[rb, 0] + a[ra, 1] * a[rb, 1] + a[ra, 2] * a[rb, 2]
                       + a[ra, 3] * a[rb, 3])
    return cos_half


@jit(inline="always")
def _cos_half2(a: F64, ra: int, rb: int, s: int) -> float:
    """As :func:`_cos_half` for side ``s`` of (n, 2, 4) quaternions."""
    cos_half: float = (a[ra, s, 0] * a[rb, s, 0] + a[ra, s, 1] * a[rb, s, 1]
                       + a[ra, s, 2] * a[rb, s, 2] + a[ra, s, 3] * a[rb, s, 3])
    return cos_half


@jit(inline="always")
def _slerped_cos(poses: PoseArrays, r0: int, r1: int, q: int) -> float:
    """Dot product of slerped quaternion ``q`` (:data:`N_SLERPED` order) of bank rows ``r0``
    and ``r1``."""
    if q == 0:
        return _cos_half(poses.pelvis_local, r0, r1)
    if q == 1:
        return _cos_half(poses.thorax, r0, r1)
    if q == 2:
        return _cos_half(poses.head, r0, r1)
    if q < 5:
        return _cos_half2(poses.leg_frame, r0, r1, q - 3)
    return _cos_half2(poses.arm_frame, r0, r1, q - 5)


@jit(nogil=True)
def pair_tables(poses: PoseArrays, next_row: I64, pair_cos: F64, pair_angle: F64) -> None:
    """Fill :class:`PlaybackBank`'s ``pair_cos`` and ``pair_angle`` (total_frames, N_SLERPED)
    for the bank ``poses`` and its ``next_row``."""
    for r in range(next_row.shape[0]):
        for q in range(N_SLERPED):
            cos_half = _slerped_cos(poses, r, next_row[r], q)
            pair_cos[r, q] = cos_half
            pair_angle[r, q] = slerp_angle(cos_half)


@jit(nogil=True)
def first_of_each_sample(rows: I64, clip: I64, time_bits: I64, loop: B1, table: I32,
                         first: I64, unique: I64) -> int:
    """Group the store rows ``rows`` (r,) by what they sample: characters playing the same
    clip from the same time (bit for bit) with the same loop flag sample the same pose. For
    each position i of ``rows``, ``first[i]`` becomes the first position with the same
    (``clip``, ``time_bits``, ``loop``) (i itself for the first); ``unique`` (m,) those first
    positions in order. Returns m. ``time_bits`` (n,) the clip times' bits
    (``time_s.view(np.int64)``); ``table`` scratch, int32 (positions, -1 for none), a power
    of two >= 2 r long (a hash table by open addressing, filled here; half the bytes of
    int64: at 19,000 rows its 256 KB of random probes stay in the second-level cache)."""
    table[:] = -1
    mask = table.shape[0] - 1
    m = 0
    for i in range(rows.shape[0]):
        c = rows[i]
        k, bits, lp = clip[c], time_bits[c], loop[c]
        key = bits + k * 1099511628211 + (1 if lp else 0)
        # Fibonacci hashing: the product's middle bits depend on every bit of the key (a time
        # on a whole frame has zero low bits).
        h = ((key * -7046029254386353131) >> 29) & mask
        while True:
            j = table[h]
            if j < 0:
                table[h] = first[i] = unique[m] = i
                m += 1
                break
            d = rows[j]
            if time_bits[d] == bits and clip[d] == k and loop[d] == lp:
                first[i] = j
                break
            h = (h + 1) & mask
    return m


#: Scratch rows of :func:`sample_rows` and :func:`place_rows` (one column per position of their
#: ``rows``; threads write disjoint columns): each sample's root before its placement (x, y,
#: z, heading), its contact weights and its sole rolls.
_ROOT = 0
_CONTACT = _ROOT + 4
_ROLL = _CONTACT + 2
PLAYBACK_SCRATCH_ROWS = _ROLL + 2

#: Rows of a block's lane scratch (:func:`sample_rows`: flat, each row :data:`.lanes.BLOCK`
#: long, one column a sample of the block): the dot products and angles of the seven slerped
#: pairs, their weights w0 and w1, the frames' weight and bank rows (whole numbers, exact in
#: float64); then the weighted sums of the seven slerped quaternions (their x in seven rows,
#: then their y, z and w) and of the ten directions (their x in ten rows, then y and z),
#: normalized in place.
_L_COS = 0
_L_ANGLE = _L_COS + N_SLERPED
_L_W0 = _L_ANGLE + N_SLERPED
_L_W1 = _L_W0 + N_SLERPED
_L_T = _L_W1 + N_SLERPED
_L_R0, _L_R1 = _L_T + 1, _L_T + 2
_L_QUAT = _L_T + 3
#: The directions a pose blends (nlerp), in the lane scratch's order: neck_dir, head_top_dir,
#: hip_dir [left, right], foot_dir [left, right], clavicle_dir [left, right], hand_dir [left,
#: right].
N_DIRECTIONS = 10
_L_DIR = _L_QUAT + 4 * N_SLERPED
LANE_ROWS = _L_DIR + 3 * N_DIRECTIONS
#: Where the quaternions' and the directions' sums start in a block's lane scratch, flat; and
#: how far apart their elements are (a row of every quaternion's x, then y: :func:`.lanes.at`).
_QUATS, _QUAT_STEP = _L_QUAT * BLOCK, N_SLERPED * BLOCK
_DIRS, _DIR_STEP = _L_DIR * BLOCK, N_DIRECTIONS * BLOCK

class PlaybackWork:
    """The arrays :func:`sample_placed` works in, kept from tick to tick (grown when the rows
    outnumber them): a tick neither allocates them nor touches fresh memory.

    ``lanes`` (size // BLOCK + 1, LANE_ROWS * BLOCK): a lane scratch per chunk of
    :func:`sample_rows` (chunks of at least :data:`.lanes.BLOCK` samples: the chunk from
    ``lo`` uses ``lanes[lo // BLOCK]``). ``loop_clip``, ``loop_count`` (store rows,) and
    ``loop_turn`` (store rows, 5): per store row, the clip and whole loops of the last loop
    transform computed for it and that transform (angle, its cosine and sine, moved x, y),
    reused while the row plays the same loop of the same clip of ``bank`` (a clip of -1:
    none); ``heading_key`` (store rows,) and ``heading_turn`` (store rows, 2): the placement
    heading last seen per store row and its cosine and sine (NaN: none)."""

    def __init__(self) -> None:
        self._size = -1
        self.table = np.zeros(0, np.int32)
        self.first = self.unique = np.zeros(0, np.int64)
        self.scratch = np.zeros((PLAYBACK_SCRATCH_ROWS, 0))
        self.lanes = np.zeros((1, LANE_ROWS * BLOCK))
        self.bank: PlaybackBank | None = None
        self.loop_clip = np.zeros(0, np.int64)
        self.loop_count = np.zeros(0)
        self.loop_turn = np.zeros((0, 5))
        self.heading_key = np.zeros(0)
        self.heading_turn = np.zeros((0, 2))

    def ensure(self, n: int, bank: PlaybackBank | None = None, store_rows: int = 0) -> None:
        """Room for ``n`` rows sampled from ``bank`` for a store of ``store_rows`` rows (the
        loop transforms kept are forgotten when the bank is another)."""
        if n > self._size:
            size = max(n, 2 * self._size, 16)
            self.table = np.empty(1 << (2 * size - 1).bit_length(), np.int32)
            self.first, self.unique = np.empty(size, np.int64), np.empty(size, np.int64)
            self.scratch = np.empty((PLAYBACK_SCRATCH_ROWS, size))
            self.lanes = np.zeros((size // BLOCK + 1, LANE_ROWS * BLOCK))
            self._size = size
        grow = store_rows > self.loop_clip.shape[0]
        if grow or bank is not self.bank:
            # Grown by half again at least: a store growing a row a tick keeps its turns.
            kept = self.loop_clip.shape[0]
            size = max(store_rows, kept * 3 // 2) if grow else kept
            self.loop_clip = np.full(size, -1, np.int64)
            self.loop_count = np.zeros(size)
            self.loop_turn = np.zeros((size, 5))
            self.heading_key = np.full(size, np.nan)
            self.heading_turn = np.zeros((size, 2))
            self.bank = bank


@jit(inline="always")
def _loop_turn(bank: PlaybackBank, k: int, loops: float, c: int, loop_clip: I64,
               loop_count: F64, loop_turn: F64) -> tuple[float, float, float, float, float]:
    """:func:`loop_transform` of clip ``k`` after ``loops`` whole loops, with the cosine and
    sine of its angle: (angle, cos, sin, moved x, moved y); kept for store row ``c`` in
    :class:`PlaybackWork`'s ``loop_*`` arrays, and read there while they hold the same clip and
    loops (the same bits: computed the same way)."""
    # The same loops to the bit: -0.0 is not 0.0 here (the angle's sign of zero follows it).
    if (loop_clip[c] == k and loop_count[c] == loops
            and math.copysign(1.0, loop_count[c]) == math.copysign(1.0, loops)):
        return (loop_turn[c, 0], loop_turn[c, 1], loop_turn[c, 2], loop_turn[c, 3],
                loop_turn[c, 4])
    angle, mx, my = loop_transform(bank.loop_yaw[k], bank.loop_cos[k], bank.loop_sin[k],
                                   bank.loop_shift[k, 0], bank.loop_shift[k, 1], loops)
    cos_a, sin_a = math.cos(angle), math.sin(angle)
    loop_clip[c], loop_count[c] = k, loops
    loop_turn[c, 0], loop_turn[c, 1], loop_turn[c, 2] = angle, cos_a, sin_a
    loop_turn[c, 3], loop_turn[c, 4] = mx, my
    return angle, cos_a, sin_a, mx, my


@jit(inline="always")
def _sampled_root(bank: PlaybackBank, k: int, r0: int, r1: int, w: float, loops: float,
                  wraps: bool, c: int, loop_clip: I64, loop_count: F64,
                  loop_turn: F64) -> tuple[Vec3, float]:
    """Root position and heading of clip ``k`` between bank rows ``r0`` and ``r1`` (weight
    ``w`` of r1) after ``loops`` whole loops, r1 in the next loop if it ``wraps`` (mirrors
    ``sample``'s root); the loop transform kept for store row ``c`` (:func:`_loop_turn`)."""
    first = bank.start[k]
    angle, cos_a, sin_a, mx, my = _loop_turn(bank, k, loops, c, loop_clip, loop_count,
                                             loop_turn)
    pa, ha = _frame_root(bank.poses, first, r0, angle, cos_a, sin_a, mx, my)
    if wraps:
        angle, mx, my = loop_transform(bank.loop_yaw[k], bank.loop_cos[k], bank.loop_sin[k],
                                       bank.loop_shift[k, 0], bank.loop_shift[k, 1],
                                       loops + 1.0)
        cos_a, sin_a = math.cos(angle), math.sin(angle)
    pb, hb = _frame_root(bank.poses, first, r1, angle, cos_a, sin_a, mx, my)
    return blend_root(pa, ha, pb, hb, w)


@jit(inline="always")
def _sum_quat(a: F64, ra: int, rb: int, w0: float, w1: float, lanes: F64, q: int,
              j: Column) -> None:
    """``w0 a[ra] + w1 a[rb]`` of the (n, 4) quaternions ``a`` into column ``j`` of ``lanes``
    as slerped quaternion ``q`` (:data:`N_SLERPED` order; a slerp given its weights,
    :func:`.lanes.slerp_weights`, before it is normalized)."""
    for e in range(4):
        lanes[at(_L_QUAT + e * N_SLERPED + q, j)] = w0 * a[ra, e] + w1 * a[rb, e]


@jit(inline="always")
def _sum_quat2(a: F64, ra: int, rb: int, s: int, w0: float, w1: float, lanes: F64, q: int,
               j: Column) -> None:
    """As :func:`_sum_quat` for side ``s`` of (n, 2, 4) quaternions."""
    for e in range(4):
        lanes[at(_L_QUAT + e * N_SLERPED + q, j)] = w0 * a[ra, s, e] + w1 * a[rb, s, e]


@jit(inline="always")
def _sum_dir(a: F64, ra: int, rb: int, w: float, lanes: F64, d: int, j: Column) -> None:
    """``(1 - w) a[ra] + w a[rb]`` of the (n, 3) directions ``a`` into column ``j`` of
    ``lanes`` as direction ``d`` (:data:`N_DIRECTIONS` order; :func:`.vec.nlerp` before it is
    normalized)."""
    for e in range(3):
        lanes[at(_L_DIR + e * N_DIRECTIONS + d, j)] = (1 - w) * a[ra, e] + w * a[rb, e]


@jit(inline="always")
def _sum_dir2(a: F64, ra: int, rb: int, s: int, w: float, lanes: F64, d: int,
              j: Column) -> None:
    """As :func:`_sum_dir` for side ``s`` of (n, 2, 3) directions."""
    for e in range(3):
        lanes[at(_L_DIR + e * N_DIRECTIONS + d, j)] = (1 - w) * a[ra, s, e] + w * a[rb, s, e]


# A call, not inlined: its two loops are the ones that run on the vector units.
@jit()
def normalize_lanes(lanes: F64) -> None:
    """The weighted sums of a block's lane scratch normalized in place, as :func:`.vec.slerp`
    and :func:`.vec.nlerp` normalize (``max(|v|, TINY)``, then each element divided: the same
    bits in a vector lane as alone), in two loops over every column of every quaternion and
    every direction (the columns past a last block's samples too: they are not read)."""
    for k in range(_QUAT_STEP):
        m = Column(_QUATS + k)
        x, y = lanes[m], lanes[m + Column(_QUAT_STEP)]
        z, w = lanes[m + Column(2 * _QUAT_STEP)], lanes[m + Column(3 * _QUAT_STEP)]
        n = max(math.sqrt(x * x + y * y + z * z + w * w), TINY)
        lanes[m], lanes[m + Column(_QUAT_STEP)] = x / n, y / n
        lanes[m + Column(2 * _QUAT_STEP)], lanes[m + Column(3 * _QUAT_STEP)] = z / n, w / n
    for k in range(_DIR_STEP):
        m = Column(_DIRS + k)
        x, y, z = lanes[m], lanes[m + Column(_DIR_STEP)], lanes[m + Column(2 * _DIR_STEP)]
        n = max(math.sqrt(x * x + y * y + z * z), TINY)
        lanes[m], lanes[m + Column(_DIR_STEP)] = x / n, y / n
        lanes[m + Column(2 * _DIR_STEP)] = z / n


@jit(inline="always")
def _slerp_weights_lanes(lanes: F64, count: Column) -> None:
    """The slerps' weights w0, w1 (:func:`.lanes.slerp_weights`) of columns ``0..count-1`` of
    a block's lane scratch, in loops over the columns (the vector units')."""
    for q in range(N_SLERPED):
        for k in range(count):
            j = Column(k)
            lanes[at(_L_W0 + q, j)], lanes[at(_L_W1 + q, j)] = slerp_weights(
                lanes[at(_L_COS + q, j)], lanes[at(_L_ANGLE + q, j)], lanes[at(_L_T, j)])


@jit(inline="always")
def _put_quat(lanes: F64, q: int, j: Column, a: F64, o: int) -> None:
    """Slerped quaternion ``q`` of column ``j`` of ``lanes`` into row ``o`` of the (n, 4)
    ``a``."""
    for e in range(4):
        a[o, e] = lanes[at(_L_QUAT + e * N_SLERPED + q, j)]


@jit(inline="always")
def _put_quat2(lanes: F64, q: int, j: Column, a: F64, o: int, s: int) -> None:
    """As :func:`_put_quat` into side ``s`` of the (n, 2, 4) ``a``."""
    for e in range(4):
        a[o, s, e] = lanes[at(_L_QUAT + e * N_SLERPED + q, j)]


@jit(inline="always")
def _put_dir(lanes: F64, d: int, j: Column, a: F64, o: int) -> None:
    """Direction ``d`` of column ``j`` of ``lanes`` into row ``o`` of the (n, 3) ``a``."""
    for e in range(3):
        a[o, e] = lanes[at(_L_DIR + e * N_DIRECTIONS + d, j)]


@jit(inline="always")
def _put_dir2(lanes: F64, d: int, j: Column, a: F64, o: int, s: int) -> None:
    """As :func:`_put_dir` into side ``s`` of the (n, 2, 3) ``a``."""
    for e in range(3):
        a[o, s, e] = lanes[at(_L_DIR + e * N_DIRECTIONS + d, j)]


@jit(inline="always")
def _lerp_n(a: F64, ra: int, rb: int, w: float, out: F64, ro: int, size: int) -> None:
    """Row ``ro`` of the (n, size) ``out``: ``(1 - w) a[ra] + w a[rb]`` (``size`` a constant:
    unrolled)."""
    for k in range(size):
        out[ro, k] = (1 - w) * a[ra, k] + w * a[rb, k]


@jit(inline="always")
def _sum_row(poses: PoseArrays, r0: int, r1: int, w: float, lanes: F64, j: Column) -> None:
    """The weighted sums of bank rows ``r0``, ``r1`` (weight ``w`` of r1; the slerps' weights
    in the lane scratch) into column ``j`` of ``lanes``, in :data:`_L_QUAT`'s and
    :data:`_L_DIR`'s order."""
    _sum_quat(poses.pelvis_local, r0, r1, lanes[at(_L_W0, j)], lanes[at(_L_W1, j)], lanes,
              0, j)
    _sum_quat(poses.thorax, r0, r1, lanes[at(_L_W0 + 1, j)], lanes[at(_L_W1 + 1, j)], lanes,
              1, j)
    _sum_quat(poses.head, r0, r1, lanes[at(_L_W0 + 2, j)], lanes[at(_L_W1 + 2, j)], lanes,
              2, j)
    for s in range(2):
        _sum_quat2(poses.leg_frame, r0, r1, s, lanes[at(_L_W0 + 3 + s, j)],
                   lanes[at(_L_W1 + 3 + s, j)], lanes, 3 + s, j)
        _sum_quat2(poses.arm_frame, r0, r1, s, lanes[at(_L_W0 + 5 + s, j)],
                   lanes[at(_L_W1 + 5 + s, j)], lanes, 5 + s, j)
    _sum_dir(poses.neck_dir, r0, r1, w, lanes, 0, j)
    _sum_dir(poses.head_top_dir, r0, r1, w, lanes, 1, j)
    for s in range(2):
        _sum_dir2(poses.hip_dir, r0, r1, s, w, lanes, 2 + s, j)
        _sum_dir2(poses.foot_dir, r0, r1, s, w, lanes, 4 + s, j)
        _sum_dir2(poses.clavicle_dir, r0, r1, s, w, lanes, 6 + s, j)
        _sum_dir2(poses.hand_dir, r0, r1, s, w, lanes, 8 + s, j)


@jit(inline="always")
def _put_row(poses: PoseArrays, r0: int, r1: int, w: float, lanes: F64, j: Column,
             out: PoseArrays, o: int) -> None:
    """Row ``o`` of ``out``: the normalized quaternions and directions of column ``j`` of
    ``lanes`` (:func:`_sum_row`'s order), and the lerped fractions, spine points and stretch
    of bank rows ``r0``, ``r1`` (weight ``w`` of r1)."""
    _put_quat(lanes, 0, j, out.pelvis_local, o)
    _put_quat(lanes, 1, j, out.thorax, o)
    _put_quat(lanes, 2, j, out.head, o)
    for s in range(2):
        _put_quat2(lanes, 3 + s, j, out.leg_frame, o, s)
        _put_quat2(lanes, 5 + s, j, out.arm_frame, o, s)
    _put_dir(lanes, 0, j, out.neck_dir, o)
    _put_dir(lanes, 1, j, out.head_top_dir, o)
    for s in range(2):
        _put_dir2(lanes, 2 + s, j, out.hip_dir, o, s)
        _put_dir2(lanes, 4 + s, j, out.foot_dir, o, s)
        _put_dir2(lanes, 6 + s, j, out.clavicle_dir, o, s)
        _put_dir2(lanes, 8 + s, j, out.hand_dir, o, s)
    _lerp_n(poses.leg_fraction, r0, r1, w, out.leg_fraction, o, 2)
    _lerp_n(poses.arm_fraction, r0, r1, w, out.arm_fraction, o, 2)
    for p in range(3):
        for k in range(3):
            out.spine_points[o, p, k] = ((1 - w) * poses.spine_points[r0, p, k]
                                         + w * poses.spine_points[r1, p, k])
    _lerp_n(poses.stretch, r0, r1, w, out.stretch, o, N_LENGTHS)


@jit(nogil=True)
def sample_rows(lo: int, hi: int, unique: I64, rows: I64, bank: PlaybackBank, clip: I64,
                time_s: F64, loop: B1, out: PoseArrays, out_rows: I64, scratch: F64,
                lanes: F64, loop_clip: I64, loop_count: F64, loop_turn: F64, placed: bool,
                placement_xy: F64, placement_heading: F64, lengths: F64, contact_weight: F64,
                sole_roll: F64, heading_key: F64, heading_turn: F64) -> None:
    """Mirrors ``sample(bank, clip, time_s, loop)`` for the store rows ``rows[unique[lo:hi]]``:
    every field but the root's into rows ``out_rows[unique[j]]`` of ``out``; into the scratch
    column ``unique[j]``, the root before its placement (capture ground taken out, as
    ``MotionPlayback`` does) and the contact weights and sole rolls
    (:func:`ecs_anim.motion.sampling.sample_table`), which :func:`place_rows` then places.
    ``placed``: every position of ``rows`` samples its own pose (``unique`` is ``0..len(rows)
    - 1``): each row is placed here as :func:`place_rows` places it, from ``placement_xy``,
    ``placement_heading``, ``lengths``, ``heading_key`` and ``heading_turn`` (its arguments),
    its contact weights and sole rolls into ``contact_weight`` and ``sole_roll``, and the
    scratch is not written (a second pass over the rows and the scratch, 0.05 ms at 4,000).

    Per store row: ``clip`` (n,) int64, ``time_s`` (n,) s, ``loop`` (n,) bool. ``scratch``
    (PLAYBACK_SCRATCH_ROWS, len(rows)); ``lanes`` :class:`PlaybackWork`'s (the chunk uses
    ``lanes[lo // BLOCK]``: chunks of at least :data:`.lanes.BLOCK` samples), ``loop_*`` its
    loop transforms kept per store row. By blocks of :data:`.lanes.BLOCK` samples: frames,
    roots, tables and the weighted sums row by row, the slerps' weights (sines: their angles
    come from the bank) and the sums' normalizations (square roots and divisions) in loops
    over the block that run on the vector units, then each row's results written."""
    poses = bank.poses
    block_lanes = lanes[lo // BLOCK]
    for block in range(lo, hi, BLOCK):
        stop = min(block + BLOCK, hi)
        count = Column(stop - block)
        for b in range(block, stop):
            j = Column(b - block)
            i = unique[b]
            c = rows[i]
            k = clip[c]
            i0, i1, w, loops, wraps = frame_position(bank.n_frames[k], bank.fps[k], time_s[c],
                                                     loop[c])
            r0, r1 = bank.start[k] + i0, bank.start[k] + i1
            p, h = _sampled_root(bank, k, r0, r1, w, loops, wraps, c, loop_clip, loop_count,
                                 loop_turn)
            ground = bank.capture_ground[r0] + w * (bank.capture_ground[r1]
                                                    - bank.capture_ground[r0])
            if placed:
                _place_root(p[0], p[1], p[2] - ground, h, c, out_rows[i], placement_xy,
                            placement_heading, lengths, out, heading_key, heading_turn)
            else:
                scratch[_ROOT, i], scratch[_ROOT + 1, i] = p[0], p[1]
                scratch[_ROOT + 2, i], scratch[_ROOT + 3, i] = p[2] - ground, h
            for s in range(2):
                a, d = bank.contact_weight[r0, s], bank.contact_weight[r1, s]
                weight = a + w * (d - a)
                a, d = bank.sole_roll[r0, s], bank.sole_roll[r1, s]
                roll = a + w * (d - a)
                if placed:
                    contact_weight[c, s], sole_roll[c, s] = weight, roll
                else:
                    scratch[_CONTACT + s, i], scratch[_ROLL + s, i] = weight, roll
            block_lanes[at(_L_T, j)] = w
            block_lanes[at(_L_R0, j)], block_lanes[at(_L_R1, j)] = r0, r1
            if r1 == bank.next_row[r0]:
                for q in range(N_SLERPED):
                    block_lanes[at(_L_COS + q, j)] = bank.pair_cos[r0, q]
                    block_lanes[at(_L_ANGLE + q, j)] = bank.pair_angle[r0, q]
            else:  # a clip held on its last frame: r1 is r0
                for q in range(N_SLERPED):
                    cos_half = _slerped_cos(poses, r0, r1, q)
                    block_lanes[at(_L_COS + q, j)] = cos_half
                    block_lanes[at(_L_ANGLE + q, j)] = slerp_angle(cos_half)
        _slerp_weights_lanes(block_lanes, count)
        for b in range(block, stop):
            j = Column(b - block)
            r0, r1 = int(block_lanes[at(_L_R0, j)]), int(block_lanes[at(_L_R1, j)])
            _sum_row(poses, r0, r1, block_lanes[at(_L_T, j)], block_lanes, j)
        normalize_lanes(block_lanes)
        for b in range(block, stop):
            j = Column(b - block)
            r0, r1 = int(block_lanes[at(_L_R0, j)]), int(block_lanes[at(_L_R1, j)])
            _put_row(poses, r0, r1, block_lanes[at(_L_T, j)], block_lanes, j, out,
                     out_rows[unique[b]])


# The copies take their row length as a constant: LLVM unrolls them (twice as fast as a loop
# over the array's shape). They go field by field: one array written at a time, where a row at
# a time wrote fifteen (12-15 % less of MotionPlayback's time in the bench's tick, its arrays
# out of the caches).
@jit(inline="always")
def _copy_shared(a: F64, lo: int, hi: int, first: I64, out_rows: I64, size: int) -> None:
    """For each position i in ``lo..hi`` whose sample is another's (``first[i]``), row
    ``out_rows[first[i]]`` of ``a`` (n, size) copied into row ``out_rows[i]``."""
    for i in range(lo, hi):
        f = first[i]
        if f != i:
            ra, rb = out_rows[f], out_rows[i]
            for k in range(size):
                a[rb, k] = a[ra, k]


@jit(inline="always")
def _copy_shared2(a: F64, lo: int, hi: int, first: I64, out_rows: I64, sides: int,
                  size: int) -> None:
    """As :func:`_copy_shared` for ``a`` (n, sides, size)."""
    for i in range(lo, hi):
        f = first[i]
        if f != i:
            ra, rb = out_rows[f], out_rows[i]
            for s in range(sides):
                for k in range(size):
                    a[rb, s, k] = a[ra, s, k]


@jit(inline="always")
def copy_shared_parts(out: PoseArrays, lo: int, hi: int, first: I64, out_rows: I64) -> None:
    """:func:`_copy_shared` of every field of ``out`` but the root's."""
    _copy_shared(out.pelvis_local, lo, hi, first, out_rows, 4)
    _copy_shared2(out.hip_dir, lo, hi, first, out_rows, 2, 3)
    _copy_shared2(out.leg_frame, lo, hi, first, out_rows, 2, 4)
    _copy_shared(out.leg_fraction, lo, hi, first, out_rows, 2)
    _copy_shared2(out.foot_dir, lo, hi, first, out_rows, 2, 3)
    _copy_shared2(out.spine_points, lo, hi, first, out_rows, 3, 3)
    _copy_shared(out.thorax, lo, hi, first, out_rows, 4)
    _copy_shared(out.neck_dir, lo, hi, first, out_rows, 3)
    _copy_shared(out.head, lo, hi, first, out_rows, 4)
    _copy_shared(out.head_top_dir, lo, hi, first, out_rows, 3)
    _copy_shared2(out.clavicle_dir, lo, hi, first, out_rows, 2, 3)
    _copy_shared2(out.arm_frame, lo, hi, first, out_rows, 2, 4)
    _copy_shared(out.arm_fraction, lo, hi, first, out_rows, 2)
    _copy_shared2(out.hand_dir, lo, hi, first, out_rows, 2, 3)
    _copy_shared(out.stretch, lo, hi, first, out_rows, N_LENGTHS)


@jit(inline="always")
def _heading_turn(heading: float, c: int, heading_key: F64,
                  heading_turn: F64) -> tuple[float, float]:
    """The cosine and sine of ``heading`` (rad), kept for store row ``c`` in
    :class:`PlaybackWork`'s ``heading_key`` and ``heading_turn`` and read there while the row's
    heading is the same (to the bit: a zero's sign too)."""
    key = heading_key[c]
    if key == heading and math.copysign(1.0, key) == math.copysign(1.0, heading):
        return heading_turn[c, 0], heading_turn[c, 1]
    cos_h, sin_h = math.cos(heading), math.sin(heading)
    heading_key[c], heading_turn[c, 0], heading_turn[c, 1] = heading, cos_h, sin_h
    return cos_h, sin_h


@jit(inline="always")
def _place_root(x: float, y: float, z: float, heading_sampled: float, c: int, o: int,
                placement_xy: F64, placement_heading: F64, lengths: F64, out: PoseArrays,
                heading_key: F64, heading_turn: F64) -> None:
    """Row ``o`` of ``out``'s root: the sampled root (``x``, ``y``, ``z``, ``heading_sampled``,
    capture ground taken out) placed as ``MotionPlayback._placed`` places store row ``c``'s
    (:func:`place_rows`' arguments)."""
    heading, scale = placement_heading[c], leg_length(lengths[c])
    cos_h, sin_h = _heading_turn(heading, c, heading_key, heading_turn)
    # rotate_xy, its cosine and sine kept
    px, py = _turned(x * scale, y * scale, cos_h, sin_h)
    out.root_position[o, 0] = (px + placement_xy[c, 0]) / scale
    out.root_position[o, 1] = (py + placement_xy[c, 1]) / scale
    out.root_position[o, 2] = z
    out.root_heading[o] = heading_sampled + heading


@jit(nogil=True)
def place_rows(lo: int, hi: int, rows: I64, first: I64, placement_xy: F64,
               placement_heading: F64, lengths: F64, out: PoseArrays, out_rows: I64,
               scratch: F64, contact_weight: F64, sole_roll: F64, heading_key: F64,
               heading_turn: F64) -> None:
    """For each position i in ``lo..hi`` of the store rows ``rows``: row ``out_rows[i]`` of
    ``out`` becomes the pose :func:`sample_rows` sampled for position ``first[i]`` (copied
    unless it is i's own), its root placed as ``MotionPlayback._placed`` does (rotated about
    the motion's origin by ``placement_heading`` (n,) rad in metres of the leg length of
    ``lengths`` (n, N_LENGTHS) m, then shifted by ``placement_xy`` (n, 2) m);
    ``contact_weight`` and ``sole_roll`` (n, 2) of store row ``rows[i]`` its sample's.
    ``heading_key``, ``heading_turn``: :class:`PlaybackWork`'s headings' cosines and sines
    kept per store row (:func:`_heading_turn`). Called only where some position's sample is
    another's (else :func:`sample_rows` places every row itself)."""
    copy_shared_parts(out, lo, hi, first, out_rows)
    for i in range(lo, hi):
        c, f = rows[i], first[i]
        _place_root(scratch[_ROOT, f], scratch[_ROOT + 1, f], scratch[_ROOT + 2, f],
                    scratch[_ROOT + 3, f], c, out_rows[i], placement_xy, placement_heading,
                    lengths, out, heading_key, heading_turn)
        for s in range(2):
            contact_weight[c, s] = scratch[_CONTACT + s, f]
            sole_roll[c, s] = scratch[_ROLL + s, f]


@jit(nogil=True)
def advance_clocks(rows: I64, dt: float, speed: F64, fade_speed: F64, clip_time_s: F64,
                   fade_time_s: F64, fade_elapsed_s: F64) -> None:
    """``MotionPlayback``'s clocks after a tick of ``dt`` s for the store rows ``rows`` (r,):
    ``clip_time_s`` and ``fade_time_s`` (n,) moved on by ``dt`` times ``speed`` and
    ``fade_speed`` (n,), ``fade_elapsed_s`` (n,) by ``dt``, in place (numpy's ``+= dt *
    speed``, bit for bit). Called directly: a pass over the rows costs less than a hand-over."""
    for c in rows:
        clip_time_s[c] += dt * speed[c]
        fade_time_s[c] += dt * fade_speed[c]
        fade_elapsed_s[c] += dt


def sample_placed(bank: PlaybackBank, rows: I64, clip: I64, time_s: F64, loop: B1,
                  placement_xy: F64, placement_heading: F64, lengths: F64, out: PoseArrays,
                  out_rows: I64, contact_weight: F64, sole_roll: F64,
                  work: PlaybackWork) -> None:
    """Mirrors ``MotionPlayback._placed(sample(bank, clip, time_s, loop), placement_xy,
    placement_heading)`` less the capture ground (``sample_table(bank, bank.capture_ground,
    ...)``) for the store rows ``rows`` (r,), into rows ``out_rows`` (r,) of ``out``, and
    their contact weights and sole rolls (``sample_table`` of the bank's) into rows ``rows``
    of ``contact_weight`` and ``sole_roll`` (n, 2).

    Per store row: ``clip`` (n,) int64, ``time_s`` (n,) s (contiguous float64), ``loop``
    (n,) bool, ``placement_xy`` (n, 2) m, ``placement_heading`` (n,) rad, ``lengths`` (n,
    N_LENGTHS) m (the leg length is the root path's unit). Each (clip, time, loop) is sampled
    once (:func:`first_of_each_sample`, :func:`sample_rows`), then every row placed
    (:func:`place_rows`; by :func:`sample_rows` as it samples where no two rows share a
    sample); ``work`` holds the scratch."""
    work.ensure(rows.size, bank, clip.shape[0])
    m = first_of_each_sample(rows, clip, time_s.view(np.int64), loop, work.table, work.first,
                             work.unique)
    # Every sample its own (a crowd out of step, the bench's): each placed as it is sampled.
    placed = m == rows.size
    over_chunks(sample_rows, m, work.unique, rows, bank, clip, time_s, loop, out, out_rows,
                work.scratch, work.lanes, work.loop_clip, work.loop_count, work.loop_turn,
                placed, placement_xy, placement_heading, lengths, contact_weight, sole_roll,
                work.heading_key, work.heading_turn, rows_per_thread=BLOCK)
    if not placed:
        over_chunks(place_rows, rows.size, rows, work.first, placement_xy, placement_heading,
                    lengths, out, out_rows, work.scratch, contact_weight, sole_roll,
                    work.heading_key, work.heading_turn)


@jit(nogil=True)
def blend_rows(lo: int, hi: int, rows: I64, old: PoseArrays, w: F64, out: PoseArrays) -> None:
    """Mirrors :func:`ecs_anim.motion.sampling.blend` (``blend(old, out, w)``) in place over the store
    rows ``rows[lo:hi]``: row ``c = rows[i]`` of ``out`` becomes row ``i`` of ``old``
    blended into it with the weight ``w[i]`` (in [0, 1]) of ``out``'s own pose."""
    for i in range(lo, hi):
        blend_row(old, i, w[i], out, rows[i])


@jit()
def blend_row(old: PoseArrays, i: int, w: float, out: PoseArrays, c: int) -> None:
    """Row ``c`` of ``out`` becomes row ``i`` of ``old`` blended into it with the weight ``w``
    of its own pose (mirrors :func:`ecs_anim.motion.sampling.blend`)."""
    p, h = blend_root(load3(old.root_position[i]), old.root_heading[i],
                      load3(out.root_position[c]), out.root_heading[c], w)
    blend_parts(old, i, out, c, w, out, c)
    store3(out.root_position[c], p)
    out.root_heading[c] = h


def empty_poses(n: int) -> NormalizedPoses:
    """Uninitialized poses for ``n`` rows (for a kernel to fill)."""
    return NormalizedPoses(**{name: np.empty((n,) + trailing)
                              for name, trailing in TRAILING_SHAPES.items()})


def writable_poses(poses: NormalizedPoses, n: int) -> NormalizedPoses:
    """``poses`` (a store's), each array made a contiguous float64 array of ``n`` rows of its
    own that kernels may write in place (replaced by a copy only where it is not one)."""
    for name, trailing in TRAILING_SHAPES.items():
        a = getattr(poses, name)
        if (a.shape != (n,) + trailing or a.dtype != np.float64
                or not (a.flags.c_contiguous and a.flags.writeable and a.flags.owndata)):
            setattr(poses, name, np.array(np.broadcast_to(a, (n,) + trailing), dtype=np.float64))
    return poses
