"""Compiled playback: each character's clip sampled, placed in the world and cross-faded.

Mirrors :func:`ecs_anim.motion.sampling.sample` (frames interpolated in normalized space, root motion
carried across loops), :func:`ecs_anim.motion.sampling.sample_table`, the placement of
``MotionPlayback._placed`` and :func:`ecs_anim.motion.sampling.blend`, one store row at a time (the
sampling's slerps by blocks of characters on the vector units), writing the store's pose arrays
in place. The clip bank's poses and the store's are passed as
:class:`~ecs_anim.runtime.kernels.decode.PoseArrays`.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.normalized import TRAILING_SHAPES, NormalizedPoses
from ecs_anim.runtime.kernels.decode import PoseArrays
from ecs_anim.runtime.kernels.lanes import BLOCK, slerp_weights
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


@jit()
def loop_transform(yaw: float, shift_x: float, shift_y: float,
                   loops: float) -> tuple[float, float, float]:
    """Mirrors ``ecs_anim.motion.sampling.loop_transform`` for one character: (angle, moved x, moved
    y) of the root after ``loops`` whole loops of a clip gaining ``yaw`` and ``shift`` each."""
    shift = complex(shift_x, shift_y)
    step = complex(math.cos(yaw), math.sin(yaw))
    if abs(yaw) < 1e-9:
        series = complex(loops, 0.0)
    else:
        pr, pi = complex_power(step.real, step.imag, loops)
        series = complex(1.0 - pr, -pi) / (1.0 - step)
    moved = shift * series
    return loops * yaw, moved.real, moved.imag


@jit(inline="always")
def _frame_root(bank: PoseArrays, first: int, frame: int, angle: float, moved_x: float,
                moved_y: float) -> tuple[Vec3, float]:
    """Root position and heading of bank row ``frame`` after the loop transform (mirrors
    ``ecs_anim.motion.sampling._frame``); ``first`` the clip's first row."""
    p0x, p0y = bank.root_position[first, 0], bank.root_position[first, 1]
    p = bank.root_position[frame]
    rx, ry = rotate_xy(p[0] - p0x, p[1] - p0y, angle)
    return (p0x + moved_x + rx, p0y + moved_y + ry, p[2]), bank.root_heading[frame] + angle


#: Scratch rows of :func:`sample_placed_rows` (one column per character of its chunk): the dot
#: products of the seven slerped quaternion pairs, their weights w0 and w1, the frames' weight,
#: the bank rows of the two frames (whole numbers, exact in float64).
_COS, _W0, _W1, _T, _R0, _R1 = 0, 7, 14, 21, 22, 23
PLAYBACK_SCRATCH_ROWS = 24


def playback_scratch(n: int) -> F64:
    """The scratch :func:`sample_placed_rows` needs for ``n`` rows: (PLAYBACK_SCRATCH_ROWS, n)."""
    return np.empty((PLAYBACK_SCRATCH_ROWS, n))


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
def _sampled_frames(c: int, start: I64, n_frames: I64, fps: F64, clip: I64, time_s: F64,
                    loop: B1) -> tuple[int, int, float, float, bool]:
    """Bank rows (r0, r1) of the frames store row ``c`` falls between, the weight of r1, the
    whole loops done and whether r1 wraps (:func:`frame_position` in bank rows)."""
    k = clip[c]
    i0, i1, w, loops, wraps = frame_position(n_frames[k], fps[k], time_s[c], loop[c])
    return start[k] + i0, start[k] + i1, w, loops, wraps


@jit(inline="always")
def _placed_root_row(c: int, bank: PoseArrays, start: I64, n_frames: I64, fps: F64,
                     loop_yaw: F64, loop_shift: F64, clip: I64, time_s: F64, loop: B1,
                     placement_xy: F64, placement_heading: F64, leg: F64, out: PoseArrays,
                     o: int) -> tuple[int, int, float]:
    """The root of ``MotionPlayback._placed(sample(...))`` for store row ``c`` (root motion
    carried across loops, then placed), into row ``o`` of ``out``. Arguments as for
    :func:`sample_placed_rows`. Returns the bank rows of the two frames and the second's
    weight."""
    r0, r1, w, loops, wraps = _sampled_frames(c, start, n_frames, fps, clip, time_s, loop)
    k = clip[c]
    first = start[k]
    angle, mx, my = loop_transform(loop_yaw[k], loop_shift[k, 0], loop_shift[k, 1], loops)
    pa, ha = _frame_root(bank, first, r0, angle, mx, my)
    if wraps:
        angle, mx, my = loop_transform(loop_yaw[k], loop_shift[k, 0], loop_shift[k, 1],
                                       loops + 1.0)
    pb, hb = _frame_root(bank, first, r1, angle, mx, my)
    p, h = blend_root(pa, ha, pb, hb, w)
    # MotionPlayback._placed: rotate the root path about the motion origin, then shift it.
    heading, scale = placement_heading[c], leg[c]
    x, y = rotate_xy(p[0] * scale, p[1] * scale, heading)
    store3(out.root_position[o], ((x + placement_xy[c, 0]) / scale,
                                  (y + placement_xy[c, 1]) / scale, p[2]))
    out.root_heading[o] = h + heading
    return r0, r1, w


@jit(nogil=True)
def sample_placed_rows(lo: int, hi: int, rows: I64, bank: PoseArrays, start: I64, n_frames: I64,
                       fps: F64, loop_yaw: F64, loop_shift: F64, clip: I64, time_s: F64, loop: B1,
                       placement_xy: F64, placement_heading: F64, leg: F64, out: PoseArrays,
                       out_rows: I64, scratch: F64) -> None:
    """Mirrors ``MotionPlayback._placed(sample(bank, clip, time_s, loop), placement_xy,
    placement_heading)`` over the store rows ``rows[lo:hi]``, into rows ``out_rows`` of
    ``out``.

    ``bank``: the clip bank's poses (total_frames,); ``start``, ``n_frames`` (n_clips,) int64,
    ``fps``, ``loop_yaw`` (n_clips,), ``loop_shift`` (n_clips, 2): as in
    :class:`ecs_anim.motion.sampling.ClipBank`. Per store row: ``clip`` (n,) int64, ``time_s`` (n,) s,
    ``loop`` (n,) bool, ``placement_xy`` (n, 2) m, ``placement_heading`` (n,) rad, ``leg`` (n,)
    leg length (m). ``scratch`` (PLAYBACK_SCRATCH_ROWS, len(rows)): :func:`playback_scratch`.

    By blocks of :data:`.lanes.BLOCK` rows: the roots and the quaternions' dot products row by
    row, the slerps' weights (their arc cosines and sines, most of the work) in a loop over the
    block's characters that runs on the vector units, then the weighted sums row by row.
    """
    for block in range(lo, hi, BLOCK):
        stop = min(block + BLOCK, hi)
        for i in range(block, stop):
            r0, r1, w = _placed_root_row(rows[i], bank, start, n_frames, fps, loop_yaw,
                                         loop_shift, clip, time_s, loop, placement_xy,
                                         placement_heading, leg, out, out_rows[i])
            scratch[_T, i], scratch[_R0, i], scratch[_R1, i] = w, r0, r1
            scratch[_COS, i] = _cos_half(bank.pelvis_local, r0, r1)
            scratch[_COS + 1, i] = _cos_half(bank.thorax, r0, r1)
            scratch[_COS + 2, i] = _cos_half(bank.head, r0, r1)
            for s in range(2):
                scratch[_COS + 3 + s, i] = _cos_half2(bank.leg_frame, r0, r1, s)
                scratch[_COS + 5 + s, i] = _cos_half2(bank.arm_frame, r0, r1, s)
        t = scratch[_T, block:stop]
        for q in range(_W0 - _COS):
            cos_half = scratch[_COS + q, block:stop]
            w0, w1 = scratch[_W0 + q, block:stop], scratch[_W1 + q, block:stop]
            # The vectorized loop (indices from 0: LLVM knows they need no wrapping around).
            for j in range(t.shape[0]):
                w0[j], w1[j] = slerp_weights(cos_half[j], t[j])
        for i in range(block, stop):
            o, w = out_rows[i], scratch[_T, i]
            r0, r1 = int(scratch[_R0, i]), int(scratch[_R1, i])
            _weighted_quat(bank.pelvis_local, r0, r1, scratch[_W0, i], scratch[_W1, i],
                           out.pelvis_local, o)
            _weighted_quat(bank.thorax, r0, r1, scratch[_W0 + 1, i], scratch[_W1 + 1, i],
                           out.thorax, o)
            _weighted_quat(bank.head, r0, r1, scratch[_W0 + 2, i], scratch[_W1 + 2, i],
                           out.head, o)
            for s in range(2):
                _weighted_quat2(bank.leg_frame, r0, r1, s, scratch[_W0 + 3 + s, i],
                                scratch[_W1 + 3 + s, i], out.leg_frame, o)
                _weighted_quat2(bank.arm_frame, r0, r1, s, scratch[_W0 + 5 + s, i],
                                scratch[_W1 + 5 + s, i], out.arm_frame, o)
            _blend_unslerped(bank, r0, bank, r1, w, out, o)


@jit(nogil=True)
def sample_table_rows(lo: int, hi: int, rows: I64, table: F64, start: I64, n_frames: I64, fps: F64,
                      clip: I64, time_s: F64, loop: B1, out: F64) -> None:
    """Mirrors :func:`ecs_anim.motion.sampling.sample_table` over the store rows
    ``rows[lo:hi]``: ``table`` (total_frames, k) interpolated at each row's clip time into
    ``out[c]`` ((n, k)). Bank and row arguments as for :func:`sample_placed_rows`."""
    for i in range(lo, hi):
        c = rows[i]
        k = clip[c]
        i0, i1, w, _, _ = frame_position(n_frames[k], fps[k], time_s[c], loop[c])
        a, b = table[start[k] + i0], table[start[k] + i1]
        for j in range(table.shape[1]):
            out[c, j] = a[j] + w * (b[j] - a[j])


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
