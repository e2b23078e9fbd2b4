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
from ecs_anim.runtime.kernels.posture import all_finite, posture_of_decoded_row
from ecs_anim.runtime.kernels.vec import copy_row, jit

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
B8 = NDArray[np.bool_]


@jit(nogil=True)
def posture_solved_rows(lo: int, hi: int, rows: I64, solved: DecodedArrays, pose: PoseArrays,
                        lengths: F64, decoded: DecodedArrays, frozen: B8, newly_bad: B8,
                        positions: F64, rotations: bool, world: F64, local: F64, rest_hips: F64,
                        bvh_from_world: F64, rest2body: F64, parents: I64, vertebrae: F64,
                        have_previous: bool) -> None:
    """:func:`ecs_anim.runtime.kernels.posture.posture_rows` over the store rows ``rows`` (r,) that the
    solver moved (``rows[lo:hi]``), in place: row ``rows[i]`` of ``decoded`` is row ``i`` of
    ``solved`` (the solver's decoded result, (r, ...)) instead of a decode of ``pose`` (its
    positions row in ``decoded`` only for a result that is not finite); the other arguments
    and results as there."""
    joints, pelvis2world, thorax2world = decoded.positions, decoded.pelvis2world, decoded.thorax2world
    head2world, leg2world, arm2world = decoded.head2world, decoded.leg2world, decoded.arm2world
    for i in range(lo, hi):
        c = rows[i]
        # A finite result is published as it is: its joints go straight into ``positions``
        # (the row then copied onto itself), not through the decode's scratch (2 MB written
        # and read back at 4,000 characters). One that may be frozen instead (the last
        # published joints kept: joints not finite, or rotations, which may not be) goes into
        # the scratch, as a decode's would.
        into = positions if not rotations and all_finite(solved.positions[i]) else joints
        copy_row(into, c, solved.positions, i)
        copy_row(pelvis2world, c, solved.pelvis2world, i)
        copy_row(thorax2world, c, solved.thorax2world, i)
        copy_row(head2world, c, solved.head2world, i)
        copy_row(leg2world, c, solved.leg2world, i)
        copy_row(arm2world, c, solved.arm2world, i)
        posture_of_decoded_row(c, pose, lengths,
                               DecodedArrays(into, pelvis2world, thorax2world, head2world,
                                             leg2world, arm2world),
                               frozen, newly_bad, positions, rotations, world, local, rest_hips,
                               bvh_from_world, rest2body, parents, vertebrae, have_previous)
