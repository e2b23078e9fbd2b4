"""Math for the loops over blocks of characters that compile to packed (SIMD) instructions.

A kernel that wants the vector units runs its per-character scalar work one row at a time as
before, but gathers what the costly arithmetic needs into a scratch of shape (k, rows) (one
column per character of its chunk: threads write disjoint columns) and runs that arithmetic in
loops ``for i in range(start, stop)`` over :data:`BLOCK` columns at a time, innermost over
characters, on contiguous memory. LLVM vectorizes such a loop only when its body calls no
function it cannot inline: the C library's ``acos``, ``sin`` and ``cos`` are calls (numba has
no vector math library here: ``numba -s`` says SVML is not loaded), so the helpers below are
polynomials, accurate to a few units in the last place on the ranges their callers give them.

No helper uses fused multiply-adds or reassociation (the kernels are not compiled with
fastmath), so a character's result is the same whether its column is computed in a vector lane
or in the scalar remainder of a loop: results do not depend on the block size or the threads.
"""

from __future__ import annotations

import math

import numpy as np

from ecs_anim.runtime.kernels.vec import (
    F64,
    TINY,
    Frame,
    Quat,
    Vec3,
    add_scaled,
    cross,
    dot,
    jit,
    norm,
    normalize,
)

#: Characters a block loop runs over at a time: its scratch columns stay in the first-level
#: cache (22 rows of 32 float64 are 5.6 kB) and it is a whole number of 8-wide AVX-512 vectors.
BLOCK = 32
#: A column of a block's flat scratch (unsigned: numba adds no wrap-around of negative indices,
#: which would stop LLVM from vectorizing the loops over columns).
Column = np.uint64

#: Taylor coefficients of asin x = sum c_k x^(2k+1), c_k = (2k)! / (4^k (k!)^2 (2k + 1)); for
#: |x| <= 0.5 the terms after the 22nd are below 1e-17 of the result.
_ASIN_TAYLOR = np.array([math.factorial(2 * k) / (4**k * math.factorial(k) ** 2 * (2 * k + 1))
                         for k in range(22)])
#: Taylor coefficients of sin x = sum s_k x^(2k+1), s_k = (-1)^k / (2k + 1)!; for |x| <= pi/2
#: the terms after the 11th are below 3e-16 of the result.
_SIN_TAYLOR = np.array([(-1.0) ** k / math.factorial(2 * k + 1) for k in range(11)])


@jit(inline="always")
def odd_series(x: float, coefficients: F64) -> float:
    """``sum c_k x^(2k+1)`` by Horner's rule in ``x^2`` (no library call)."""
    x2 = x * x
    acc = 0.0
    for k in range(coefficients.shape[0] - 1, -1, -1):
        acc = acc * x2 + coefficients[k]
    return x * acc


@jit()
def asin_small(x: float) -> float:
    """``asin x`` for ``|x| <= 0.5`` (its Taylor series: :func:`odd_series`)."""
    return odd_series(x, _ASIN_TAYLOR)


@jit()
def acos_unit(c: float) -> float:
    """``acos c`` for ``c`` in [0, 1], within 4e-16 relative of ``np.arccos``: ``2 asin
    sqrt((1 - c) / 2)`` above 0.5 (``1 - c`` is exact there), ``pi/2 - asin c`` below."""
    upper = c >= 0.5
    a = asin_small(math.sqrt((1.0 - c) * 0.5) if upper else c)
    return 2.0 * a if upper else 0.5 * math.pi - a


# Not .ground.sine (fdlibm's, with a reduction by pi/2, for the bumps' arguments of any size):
# the slerp's angles need none, and either one in the other's place would change results' bits.
@jit()
def sin_quarter(x: float) -> float:
    """``sin x`` for ``x`` in [-pi/2, pi/2], within 3e-16 relative of ``np.sin``."""
    return odd_series(x, _SIN_TAYLOR)


@jit(inline="always")
def slerp_angle(cos_half: float) -> float:
    """The angle of :func:`ecs_anim.core.rotations.slerp` between quaternions whose dot product
    is ``cos_half``, by the shorter arc (:func:`acos_unit` of its size, at most pi/2)."""
    return acos_unit(min(abs(cos_half), 1.0))


# Inlined by numba: as a call LLVM finds it too long to inline, and a loop with a call in it
# is not vectorized.
@jit(inline="always")
def slerp_weights(cos_half: float, theta: float, t: float) -> tuple[float, float]:
    """The weights (w0, w1) of :func:`ecs_anim.core.rotations.slerp` for quaternions whose dot
    product is ``cos_half`` and angle ``theta`` (:func:`slerp_angle`: a pair's own, so callers
    may compute it once for every ``t``) at ``t`` in [0, 1]: the slerp is ``normalize(w0 q0 +
    w1 q1)`` (``w1`` negative where the dot is: the shorter arc). As :func:`.vec.slerp`, with
    :func:`acos_unit` and :func:`sin_quarter` for the library's ``acos`` and ``sin``, so that
    a loop of it over characters is vectorized."""
    # Both weights are computed and then chosen (a branch around a polynomial stops LLVM
    # from vectorizing the loop).
    sign = -1.0 if cos_half < 0.0 else 1.0
    c = min(abs(cos_half), 1.0)
    near = (1.0 - c) * (1.0 + c) < 1e-12
    arc0, arc1 = sin_quarter((1.0 - t) * theta), sin_quarter(t * theta)
    w0 = 1.0 - t if near else arc0
    w1 = t if near else arc1
    return w0, sign * w1


# Branch-free twins of :mod:`.vec`'s helpers, for loops over a block's characters: each computes
# every case the scalar helper may branch to and then chooses (``a if c else b`` on values
# already computed is a select), with the same operations in the same order, so that its
# result is the scalar helper's to the bit.


@jit()
def pick3(cond: bool, a: Vec3, b: Vec3) -> Vec3:
    """``a if cond else b``, element by element (a select, not a branch)."""
    return (a[0] if cond else b[0], a[1] if cond else b[1], a[2] if cond else b[2])


@jit(inline="always")
def quat_from_matrix_lanes(m: Frame) -> Quat:
    """:func:`.vec.quat_from_matrix` (the same bits) without branches: the four candidate
    quaternions computed and the one of the largest diagonal chosen."""
    m00, m11, m22 = m[0][0], m[1][1], m[2][2]
    m01, m02, m10, m12, m20, m21 = m[1][0], m[2][0], m[0][1], m[2][1], m[0][2], m[1][2]
    trace = m00 + m11 + m22
    one = m00 > trace
    largest = m00 if one else trace
    two = m11 > largest
    largest = m11 if two else largest
    three = m22 > largest
    # best: 3 if three, else 2 if two, else 1 if one, else 0 (vec.quat_from_matrix's order)
    q0 = (m21 - m12, m02 - m20, m10 - m01, 1.0 + trace)
    q1 = (1.0 + m00 - m11 - m22, m01 + m10, m02 + m20, m21 - m12)
    q2 = (m01 + m10, 1.0 - m00 + m11 - m22, m12 + m21, m02 - m20)
    q3 = (m02 + m20, m12 + m21, 1.0 - m00 - m11 + m22, m10 - m01)
    x = q3[0] if three else (q2[0] if two else (q1[0] if one else q0[0]))
    y = q3[1] if three else (q2[1] if two else (q1[1] if one else q0[1]))
    z = q3[2] if three else (q2[2] if two else (q1[2] if one else q0[2]))
    w = q3[3] if three else (q2[3] if two else (q1[3] if one else q0[3]))
    n = max(math.sqrt(x * x + y * y + z * z + w * w), TINY)
    sign = -1.0 if w / n < 0.0 else 1.0
    return (sign * x / n, sign * y / n, sign * z / n, sign * w / n)


@jit(inline="always")
def rotation_between_lanes(a: Vec3, b: Vec3) -> Frame:
    """:func:`.vec.rotation_between` (the same bits) without branches: the half turn for
    opposite directions computed always and chosen where they are opposite."""
    a = normalize(a)
    b = normalize(b)
    k = cross(a, b)
    s = norm(k)
    c = dot(a, b)
    opposite = (c < -1.0 + 1e-9) & (s < 1e-6)
    first = abs(a[0]) < 0.9
    helper = (1.0 if first else 0.0, 0.0 if first else 1.0, 0.0)
    p = normalize(cross(a, helper))
    d = 1.0 / max(1.0 + c, 1e-12)
    kk = dot(k, k)
    cx = _rodrigues_lanes(k, kk, d, (1.0, 0.0, 0.0), k[0])
    cy = _rodrigues_lanes(k, kk, d, (0.0, 1.0, 0.0), k[1])
    cz = _rodrigues_lanes(k, kk, d, (0.0, 0.0, 1.0), k[2])
    hx = (2.0 * p[0] * p[0] - 1.0, 2.0 * p[1] * p[0], 2.0 * p[2] * p[0])
    hy = (2.0 * p[0] * p[1], 2.0 * p[1] * p[1] - 1.0, 2.0 * p[2] * p[1])
    hz = (2.0 * p[0] * p[2], 2.0 * p[1] * p[2], 2.0 * p[2] * p[2] - 1.0)
    return (pick3(opposite, hx, cx), pick3(opposite, hy, cy), pick3(opposite, hz, cz))


@jit()
def _rodrigues_lanes(k: Vec3, kk: float, d: float, e: Vec3, k_j: float) -> Vec3:
    """:func:`.vec._rodrigues_column` (the same operations): ``e + k x e + (k k_j - e kk) d``."""
    ke = cross(k, e)
    a = (e[0] + ke[0], e[1] + ke[1], e[2] + ke[2])
    b = (k[0] * k_j - e[0] * kk, k[1] * k_j - e[1] * kk, k[2] * k_j - e[2] * kk)
    return (a[0] + b[0] * d, a[1] + b[1] * d, a[2] + b[2] * d)


@jit()
def distal_frames_lanes(limb: Frame, mid: Vec3, end: Vec3) -> Frame:
    """:func:`.decode.distal_frames` (``vec.frame_from_axes(end - mid, limb x, 2, 0, limb y)``,
    the same bits) without branches: z along mid->end, x the limb's x made normal to it (its y
    where that is parallel to z), y = z x x."""
    p = normalize((end[0] - mid[0], end[1] - mid[1], end[2] - mid[2]))
    s = add_scaled(limb[0], p, -dot(limb[0], p))
    fallback = add_scaled(limb[1], p, -dot(limb[1], p))
    s = normalize(pick3(norm(s) < 1e-9, fallback, s))
    return (s, cross(p, s), p)


# A block's flat scratch: rows of BLOCK values, one column a character of the block.


@jit()
def at(r: int, j: Column) -> Column:
    """Where row ``r``, column ``j`` of a block's flat scratch is (its flat index: the distance
    between two rows is a constant of the compiled code, so LLVM sees that a column's rows do
    not overlap, and vectorizes the loops over columns without checks at run time)."""
    return Column(r * BLOCK) + j


@jit()
def col3(scratch: F64, r: int, j: Column) -> Vec3:
    """The 3-vector in rows ``r:r + 3`` of column ``j``."""
    return (scratch[at(r, j)], scratch[at(r + 1, j)], scratch[at(r + 2, j)])


@jit()
def put3(scratch: F64, r: int, j: Column, v: Vec3) -> None:
    """The 3-vector ``v`` into rows ``r:r + 3`` of column ``j``."""
    scratch[at(r, j)], scratch[at(r + 1, j)], scratch[at(r + 2, j)] = v[0], v[1], v[2]


@jit()
def col4(scratch: F64, r: int, j: Column) -> Quat:
    """The quaternion in rows ``r:r + 4`` of column ``j``."""
    return (scratch[at(r, j)], scratch[at(r + 1, j)], scratch[at(r + 2, j)],
            scratch[at(r + 3, j)])


@jit()
def put4(scratch: F64, r: int, j: Column, q: Quat) -> None:
    """The quaternion ``q`` into rows ``r:r + 4`` of column ``j``."""
    scratch[at(r, j)], scratch[at(r + 1, j)], scratch[at(r + 2, j)], scratch[at(r + 3, j)] = q


@jit()
def col_frame(scratch: F64, r: int, j: Column) -> Frame:
    """The frame in rows ``r:r + 9`` of column ``j`` (its axes one after the other)."""
    return (col3(scratch, r, j), col3(scratch, r + 3, j), col3(scratch, r + 6, j))


@jit()
def put_frame(scratch: F64, r: int, j: Column, m: Frame) -> None:
    put3(scratch, r, j, m[0])
    put3(scratch, r + 3, j, m[1])
    put3(scratch, r + 6, j, m[2])
