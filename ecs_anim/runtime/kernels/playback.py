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
from ecs_anim.runtime.kernels.lanes import BLOCK, slerp_angle, slerp_weights
from ecs_anim.runtime.kernels.vec import (
    F64,
    TINY,
    Vec3,
    jit,
    load3,
    nlerp,
    slerp,
    store3,
    wrap,
)

if TYPE_CHECKING:
    from ecs_anim.motion.sampling import ClipBank

I64 = NDArray[np.int64]
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
    (the shorter way round)."""
    p = ((1 - w) * pa[0] + w * pb[0], (1 - w) * pa[1] + w * pb[1], (1 - w) * pa[2] + w * pb[2])
    return p, ha + w * wrap(hb - ha)


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
def first_of_each_sample(rows: I64, clip: I64, time_bits: I64, loop: B1, table: I64,
                         first: I64, unique: I64) -> int:
    """Group the store rows ``rows`` (r,) by what they sample: characters playing the same
    clip from the same time (bit for bit) with the same loop flag sample the same pose. For
    each position i of ``rows``, ``first[i]`` becomes the first position with the same
    (``clip``, ``time_bits``, ``loop``) (i itself for the first); ``unique`` (m,) those first
    positions in order. Returns m. ``time_bits`` (n,) the clip times' bits
    (``time_s.view(np.int64)``); ``table`` scratch, a power of two >= 2 r long (a hash table
    by open addressing, filled here)."""
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
#: ``rows``; threads write disjoint columns): for the slerps of a block of samples, the dot
#: products and angles of the seven slerped pairs, their weights w0 and w1, the frames' weight
#: and bank rows (whole numbers, exact in float64); then each sample's root before its
#: placement (x, y, z, heading), its contact weights and its sole rolls.
_COS = 0
_ANGLE = _COS + N_SLERPED
_W0 = _ANGLE + N_SLERPED
_W1 = _W0 + N_SLERPED
_T = _W1 + N_SLERPED
_R0, _R1 = _T + 1, _T + 2
_ROOT = _T + 3
_CONTACT = _ROOT + 4
_ROLL = _CONTACT + 2
PLAYBACK_SCRATCH_ROWS = _ROLL + 2


class PlaybackWork:
    """The arrays :func:`sample_placed` works in, kept from tick to tick (grown when the rows
    outnumber them): a tick neither allocates them nor touches fresh memory."""

    def __init__(self) -> None:
        self._size = -1
        self.table = self.first = self.unique = np.zeros(0, np.int64)
        self.scratch = np.zeros((PLAYBACK_SCRATCH_ROWS, 0))

    def ensure(self, n: int) -> None:
        """Room for ``n`` rows."""
        if n > self._size:
            size = max(n, 2 * self._size, 16)
            self.table = np.empty(1 << (2 * size - 1).bit_length(), np.int64)
            self.first, self.unique = np.empty(size, np.int64), np.empty(size, np.int64)
            self.scratch = np.empty((PLAYBACK_SCRATCH_ROWS, size))
            self._size = size


@jit(inline="always")
def _weighted_quat(a: F64, ra: int, rb: int, w0: float, w1: float, out: F64, ro: int) -> None:
    """Row ``ro`` of the (n, 4) ``out``: ``normalize(w0 a[ra] + w1 a[rb])`` (a slerp given its
    weights, :func:`.lanes.slerp_weights`)."""
    x = w0 * a[ra, 0] + w1 * a[rb, 0]
    y = w0 * a[ra, 1] + w1 * a[rb, 1]
    z = w0 * a[ra, 2] + w1 * a[rb, 2]
    w = w0 * a[ra, 3] + w1 * a[rb, 3]
    n = max(math.sqrt(x * x + y * y + z * z + w * w), TINY)
    out[ro, 0], out[ro, 1], out[ro, 2], out[ro, 3] = x / n, y / n, z / n, w / n


@jit(inline="always")
def _weighted_quat2(a: F64, ra: int, rb: int, s: int, w0: float, w1: float, out: F64,
                    ro: int) -> None:
    """As :func:`_weighted_quat` for side ``s`` of (n, 2, 4) quaternions."""
    x = w0 * a[ra, s, 0] + w1 * a[rb, s, 0]
    y = w0 * a[ra, s, 1] + w1 * a[rb, s, 1]
    z = w0 * a[ra, s, 2] + w1 * a[rb, s, 2]
    w = w0 * a[ra, s, 3] + w1 * a[rb, s, 3]
    n = max(math.sqrt(x * x + y * y + z * z + w * w), TINY)
    out[ro, s, 0], out[ro, s, 1], out[ro, s, 2], out[ro, s, 3] = x / n, y / n, z / n, w / n


@jit(inline="always")
def _sampled_root(bank: PlaybackBank, k: int, r0: int, r1: int, w: float, loops: float,
                  wraps: bool) -> tuple[Vec3, float]:
    """Root position and heading of clip ``k`` between bank rows ``r0`` and ``r1`` (weight
    ``w`` of r1) after ``loops`` whole loops, r1 in the next loop if it ``wraps`` (mirrors
    ``sample``'s root)."""
    first, yaw, cos_yaw, sin_yaw = bank.start[k], bank.loop_yaw[k], bank.loop_cos[k], bank.loop_sin[k]
    shift_x, shift_y = bank.loop_shift[k, 0], bank.loop_shift[k, 1]
    angle, mx, my = loop_transform(yaw, cos_yaw, sin_yaw, shift_x, shift_y, loops)
    c, s = math.cos(angle), math.sin(angle)
    pa, ha = _frame_root(bank.poses, first, r0, angle, c, s, mx, my)
    if wraps:
        angle, mx, my = loop_transform(yaw, cos_yaw, sin_yaw, shift_x, shift_y, loops + 1.0)
        c, s = math.cos(angle), math.sin(angle)
    pb, hb = _frame_root(bank.poses, first, r1, angle, c, s, mx, my)
    return blend_root(pa, ha, pb, hb, w)


@jit(nogil=True)
def sample_rows(lo: int, hi: int, unique: I64, rows: I64, bank: PlaybackBank, clip: I64,
                time_s: F64, loop: B1, out: PoseArrays, out_rows: I64, scratch: F64) -> None:
    """Mirrors ``sample(bank, clip, time_s, loop)`` for the store rows ``rows[unique[lo:hi]]``:
    every field but the root's into rows ``out_rows[unique[j]]`` of ``out``; into the scratch
    column ``unique[j]``, the root before its placement (capture ground taken out, as
    ``MotionPlayback`` does) and the contact weights and sole rolls
    (:func:`ecs_anim.motion.sampling.sample_table`), which :func:`place_rows` then places.

    Per store row: ``clip`` (n,) int64, ``time_s`` (n,) s, ``loop`` (n,) bool. ``scratch``
    (PLAYBACK_SCRATCH_ROWS, len(rows)). By blocks of :data:`.lanes.BLOCK` samples: frames,
    roots and tables row by row, the slerps' weights (sines: their angles come from the
    bank) in a loop over the block that runs on the vector units, then the weighted sums row
    by row."""
    poses = bank.poses
    for block in range(lo, hi, BLOCK):
        stop = min(block + BLOCK, hi)
        for j in range(block, stop):
            i = unique[j]
            c = rows[i]
            k = clip[c]
            i0, i1, w, loops, wraps = frame_position(bank.n_frames[k], bank.fps[k], time_s[c],
                                                     loop[c])
            r0, r1 = bank.start[k] + i0, bank.start[k] + i1
            p, h = _sampled_root(bank, k, r0, r1, w, loops, wraps)
            ground = bank.capture_ground[r0] + w * (bank.capture_ground[r1]
                                                    - bank.capture_ground[r0])
            scratch[_ROOT, i], scratch[_ROOT + 1, i] = p[0], p[1]
            scratch[_ROOT + 2, i], scratch[_ROOT + 3, i] = p[2] - ground, h
            for s in range(2):
                a, b = bank.contact_weight[r0, s], bank.contact_weight[r1, s]
                scratch[_CONTACT + s, i] = a + w * (b - a)
                a, b = bank.sole_roll[r0, s], bank.sole_roll[r1, s]
                scratch[_ROLL + s, i] = a + w * (b - a)
            scratch[_T, j], scratch[_R0, j], scratch[_R1, j] = w, r0, r1
            if r1 == bank.next_row[r0]:
                for q in range(N_SLERPED):
                    scratch[_COS + q, j] = bank.pair_cos[r0, q]
                    scratch[_ANGLE + q, j] = bank.pair_angle[r0, q]
            else:  # a clip held on its last frame: r1 is r0
                for q in range(N_SLERPED):
                    cos_half = _slerped_cos(poses, r0, r1, q)
                    scratch[_COS + q, j] = cos_half
                    scratch[_ANGLE + q, j] = slerp_angle(cos_half)
        t = scratch[_T, block:stop]
        for q in range(N_SLERPED):
            dots, angles = scratch[_COS + q, block:stop], scratch[_ANGLE + q, block:stop]
            w0, w1 = scratch[_W0 + q, block:stop], scratch[_W1 + q, block:stop]
            # The vectorized loop (indices from 0: LLVM knows they need no wrapping around).
            for b in range(t.shape[0]):
                w0[b], w1[b] = slerp_weights(dots[b], angles[b], t[b])
        for j in range(block, stop):
            o, w = out_rows[unique[j]], scratch[_T, j]
            r0, r1 = int(scratch[_R0, j]), int(scratch[_R1, j])
            _weighted_quat(poses.pelvis_local, r0, r1, scratch[_W0, j], scratch[_W1, j],
                           out.pelvis_local, o)
            _weighted_quat(poses.thorax, r0, r1, scratch[_W0 + 1, j], scratch[_W1 + 1, j],
                           out.thorax, o)
            _weighted_quat(poses.head, r0, r1, scratch[_W0 + 2, j], scratch[_W1 + 2, j],
                           out.head, o)
            for s in range(2):
                _weighted_quat2(poses.leg_frame, r0, r1, s, scratch[_W0 + 3 + s, j],
                                scratch[_W1 + 3 + s, j], out.leg_frame, o)
                _weighted_quat2(poses.arm_frame, r0, r1, s, scratch[_W0 + 5 + s, j],
                                scratch[_W1 + 5 + s, j], out.arm_frame, o)
            _blend_unslerped(poses, r0, poses, r1, w, out, o)


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


@jit(nogil=True)
def place_rows(lo: int, hi: int, rows: I64, first: I64, placement_xy: F64,
               placement_heading: F64, lengths: F64, out: PoseArrays, out_rows: I64,
               scratch: F64, contact_weight: F64, sole_roll: F64) -> None:
    """For each position i in ``lo..hi`` of the store rows ``rows``: row ``out_rows[i]`` of
    ``out`` becomes the pose :func:`sample_rows` sampled for position ``first[i]`` (copied
    unless it is i's own), its root placed as ``MotionPlayback._placed`` does (rotated about
    the motion's origin by ``placement_heading`` (n,) rad in metres of the leg length of
    ``lengths`` (n, N_LENGTHS) m, then shifted by ``placement_xy`` (n, 2) m);
    ``contact_weight`` and ``sole_roll`` (n, 2) of store row ``rows[i]`` its sample's."""
    copy_shared_parts(out, lo, hi, first, out_rows)
    for i in range(lo, hi):
        c, o, f = rows[i], out_rows[i], first[i]
        heading, scale = placement_heading[c], leg_length(lengths[c])
        x, y = rotate_xy(scratch[_ROOT, f] * scale, scratch[_ROOT + 1, f] * scale, heading)
        out.root_position[o, 0] = (x + placement_xy[c, 0]) / scale
        out.root_position[o, 1] = (y + placement_xy[c, 1]) / scale
        out.root_position[o, 2] = scratch[_ROOT + 2, f]
        out.root_heading[o] = scratch[_ROOT + 3, f] + heading
        for s in range(2):
            contact_weight[c, s] = scratch[_CONTACT + s, f]
            sole_roll[c, s] = scratch[_ROLL + s, f]


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
    (:func:`place_rows`); ``work`` holds the scratch."""
    work.ensure(rows.size)
    m = first_of_each_sample(rows, clip, time_s.view(np.int64), loop, work.table, work.first,
                             work.unique)
    over_chunks(sample_rows, m, work.unique, rows, bank, clip, time_s, loop, out, out_rows,
                work.scratch)
    over_chunks(place_rows, rows.size, rows, work.first, placement_xy, placement_heading,
                lengths, out, out_rows, work.scratch, contact_weight, sole_roll)


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
