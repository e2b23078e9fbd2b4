"""PostureConvert of the characters the solver moved, from the pose the solver decoded.

The solver keeps its decoded pose in step with the pose it changes (every step updates both; a
bent spine is decoded again), so decoding the solved pose once more in PostureConvert would give
the same joints (to rounding: the tests check 1e-9 m). :func:`posture_solved_rows` mirrors
:func:`ecs_anim.kernels.posture.posture_rows` with the decode replaced by a copy of the
solver's rows; PostureConvert calls it for the solved rows and ``posture_rows`` for the others.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from .decode import DecodedArrays, PoseArrays
from .posture import (
    all_finite,
    bvh_globals_row,
    export_rotations_row,
    local_from_globals_row,
    vertebrae_row,
)

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
B8 = NDArray[np.bool_]


@njit(cache=True, nogil=True)
def posture_solved_rows(lo: int, hi: int, rows: I64, solved: DecodedArrays, pose: PoseArrays,
                        lengths: F64, decoded: DecodedArrays, frozen: B8, newly_bad: B8,
                        positions: F64, rotations: bool, world: F64, local: F64, rest_hips: F64,
                        bvh_from_world: F64, rest2body: F64, parents: I64, vertebrae: F64,
                        have_previous: bool) -> None:
    """:func:`ecs_anim.kernels.posture.posture_rows` over the store rows ``rows`` (r,) that the
    solver moved (``rows[lo:hi]``), in place: row ``rows[i]`` of ``decoded`` is row ``i`` of
    ``solved`` (the solver's decoded result, (r, ...)) instead of a decode of ``pose``; the
    other arguments and results as there."""
    count = vertebrae.shape[1]
    joints, pelvis2world, thorax2world = decoded.positions, decoded.pelvis2world, decoded.thorax2world
    head2world, leg2world, arm2world = decoded.head2world, decoded.leg2world, decoded.arm2world
    for i in range(lo, hi):
        c = rows[i]
        joints[c] = solved.positions[i]
        pelvis2world[c] = solved.pelvis2world[i]
        thorax2world[c] = solved.thorax2world[i]
        head2world[c] = solved.head2world[i]
        leg2world[c] = solved.leg2world[i]
        arm2world[c] = solved.arm2world[i]
        good = all_finite(joints[c])
        if rotations:
            export_rotations_row(c, decoded, rest_hips, world[c])
            bvh_globals_row(world[c], bvh_from_world, rest2body)
            good = good and all_finite(world[c])
        newly_bad[c] = not good and not frozen[c]
        if not good:
            frozen[c] = True
        if not frozen[c]:
            positions[c] = decoded.positions[c]
            if rotations:
                local_from_globals_row(world[c], parents, local[c])
        if count > 0 and (not frozen[c] or not have_previous):
            vertebrae_row(c, pose, lengths[c], vertebrae[c])
