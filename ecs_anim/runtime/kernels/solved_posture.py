"""PostureConvert of the characters the solver moved, from the pose the solver decoded.

The solver keeps its decoded pose in step with the pose it changes (every step updates both; a
bent spine is decoded again), so decoding the solved pose once more in PostureConvert would give
the same joints (to rounding: the tests check 1e-9 m). :func:`posture_solved_rows` mirrors
:func:`ecs_anim.runtime.kernels.posture.posture_rows` with the decode replaced by a copy of the
solver's rows; PostureConvert calls it for the solved rows and ``posture_rows`` for the others.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ecs_anim.runtime.kernels.decode import DecodedArrays, PoseArrays
from ecs_anim.runtime.kernels.posture import (
    all_finite,
    copy_positions,
    posture_of_decoded_row,
    with_positions,
)
from ecs_anim.runtime.kernels.vec import jit

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
B8 = NDArray[np.bool_]


@jit(nogil=True)
def posture_solved_rows(lo: int, hi: int, rows: I64, solved: DecodedArrays, pose: PoseArrays,
                        lengths: F64, decoded: DecodedArrays, frozen: B8, newly_bad: B8,
                        positions: F64, rotations: bool, world: F64, local: F64, rest_hips: F64,
                        bvh_from_world: F64, rest2body: F64, parents: I64, vertebrae: F64,
                        have_previous: bool, frames_shared: bool) -> None:
    """:func:`ecs_anim.runtime.kernels.posture.posture_rows` over the store rows ``rows`` (r,) that the
    solver moved (``rows[lo:hi]``), in place: row ``rows[i]`` of the frames of ``decoded`` and
    of ``positions`` is row ``i`` of ``solved`` (the solver's decoded result, (r, ...)) instead
    of a decode of ``pose``; the frames are not copied when ``frames_shared`` (those of
    ``decoded`` are ``solved``'s arrays: every row solved). ``decoded.positions`` (not
    ``positions``) is scratch, of which this chunk uses row ``lo`` with ``rotations``; a row's
    positions are written only where they are all finite; the other arguments and
    results as there."""
    posture = with_positions(decoded, positions)
    previous = decoded.positions
    for i in range(lo, hi):
        c = rows[i]
        if not frames_shared:
            copy_frames(posture, c, solved, i)
        good = all_finite(solved.positions[i])
        if good:
            if rotations:  # put back if the rotations are not finite
                copy_positions(previous, lo, positions, c)
            copy_positions(positions, c, solved.positions, i)
        posture_of_decoded_row(c, pose, lengths, posture, good, previous, lo, frozen, newly_bad,
                               rotations, world, local, rest_hips, bvh_from_world, rest2body,
                               parents, vertebrae, have_previous)


@jit(inline="always")
def copy_frames(dst: DecodedArrays, c: int, src: DecodedArrays, i: int) -> None:
    """The frames of row ``c`` of ``dst`` made those of row ``i`` of ``src`` (indices, not
    :func:`.vec.copy_row`'s flat views, whose reshape calls numba's runtime): ``pelvis2world``,
    ``thorax2world``, ``head2world`` (n, 3, 3); ``leg2world``, ``arm2world`` (n, 2, 3, 3)
    (``dst``'s n rows, ``src``'s its own)."""
    for a in range(3):
        for b in range(3):
            dst.pelvis2world[c, a, b] = src.pelvis2world[i, a, b]
            dst.thorax2world[c, a, b] = src.thorax2world[i, a, b]
            dst.head2world[c, a, b] = src.head2world[i, a, b]
            for s in range(2):
                dst.leg2world[c, s, a, b] = src.leg2world[i, s, a, b]
                dst.arm2world[c, s, a, b] = src.arm2world[i, s, a, b]
