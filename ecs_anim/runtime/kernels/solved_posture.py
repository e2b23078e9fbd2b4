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
from ecs_anim.runtime.kernels.posture import posture_of_decoded_row, with_positions
from ecs_anim.runtime.kernels.vec import copy_row, jit

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
    ``positions``) is scratch, of which this chunk uses row ``lo``; the other arguments and
    results as there."""
    posture = with_positions(decoded, positions)
    previous = decoded.positions
    for i in range(lo, hi):
        c = rows[i]
        copy_row(previous, lo, positions, c)
        copy_row(positions, c, solved.positions, i)
        if not frames_shared:
            copy_row(posture.pelvis2world, c, solved.pelvis2world, i)
            copy_row(posture.thorax2world, c, solved.thorax2world, i)
            copy_row(posture.head2world, c, solved.head2world, i)
            copy_row(posture.leg2world, c, solved.leg2world, i)
            copy_row(posture.arm2world, c, solved.arm2world, i)
        posture_of_decoded_row(c, pose, lengths, posture, previous, lo, frozen, newly_bad,
                               rotations, world, local, rest_hips, bvh_from_world, rest2body,
                               parents, vertebrae, have_previous)
