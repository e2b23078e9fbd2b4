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

from ecs_anim.runtime.kernels.vec import F64, jit

#: Characters a block loop runs over at a time: its scratch columns stay in the first-level
#: cache (22 rows of 32 float64 are 5.6 kB) and it is a whole number of 8-wide AVX-512 vectors.
BLOCK = 32

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
