"""Compiled centre of mass (COMControl's work): de Leva segment masses over joint positions.

Mirrors :func:`ecs_anim.core.morphology.centres_of_mass`. The segments' joints
(:data:`ecs_anim.core.morphology.MASS_SEGMENTS`) are the constants :data:`SEGMENT_JOINTS`, so
each row's sum is compiled with its joints' places known.
:func:`motion_of` is ConstraintSolve's pass over the motion's pose before the solve: the joints
copied, the centres of mass and the speed bound's packed values in one read of each row.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.normalized import NormalizedPoses
from ecs_anim.runtime.kernels import over_chunks
from ecs_anim.runtime.kernels.decode import PoseArrays, pose_arrays
from ecs_anim.runtime.kernels.joint_speed import pack_row, pack_rows
from ecs_anim.runtime.kernels.vec import F64, copy_row, jit
from ecs_anim.solver.joint_speed import N_VALUES

I64 = NDArray[np.int64]
B8 = NDArray[np.bool_]


#: Each mass segment's proximal and distal joint (:data:`ecs_anim.core.morphology.MASS_SEGMENTS`
#: by :data:`~ecs_anim.core.skeleton.JOINT_INDEX`), written out: the kernels compile them in as
#: constants (about 15 % off each centre of mass); a test pins them to ``MASS_SEGMENTS``, which
#: the kernel cache does not watch.
SEGMENT_JOINTS = ((0, 11), (11, 13), (1, 2), (5, 6), (2, 3), (6, 7), (3, 4), (7, 8), (14, 15),
                  (18, 19), (15, 16), (19, 20), (16, 17), (20, 21))


@jit(inline="always")
def centre_of_mass_row(p: F64, masses: F64, com_fraction: F64) -> tuple[float, float, float]:
    """Whole-body centre of mass of one posture ``p`` (N_JOINTS, 3) m, from its segments'
    ``masses`` (kg) and ``com_fraction`` (n_segments,) (mirrors one row of
    :func:`ecs_anim.core.morphology.centres_of_mass`; summed segment by segment)."""
    x = y = z = 0.0
    total = 0.0
    for s in range(len(SEGMENT_JOINTS)):
        a, b = SEGMENT_JOINTS[s]
        f, m = com_fraction[s], masses[s]
        x += m * (p[a, 0] + f * (p[b, 0] - p[a, 0]))
        y += m * (p[a, 1] + f * (p[b, 1] - p[a, 1]))
        z += m * (p[a, 2] + f * (p[b, 2] - p[a, 2]))
        total += m
    return (x / total, y / total, z / total)


@jit(nogil=True)
def centres_of_mass(lo: int, hi: int, rows: I64, position_rows: I64, positions: F64, masses: F64,
                    com_fraction: F64, out: F64) -> None:
    """Mirrors :func:`ecs_anim.core.morphology.centres_of_mass` over the store rows ``rows`` (int64)
    ``rows[lo:hi]``: the centre of mass of the posture ``positions[position_rows[i]]``
    ((m, N_JOINTS, 3), m) of store row ``c = rows[i]`` on its segments ``masses[c]`` (kg) and
    ``com_fraction[c]`` ((n, n_segments) each) into ``out[c]`` ((n, 3), m). Pass ``rows`` as
    ``position_rows`` for positions held by store row, ``arange`` for gathered ones."""
    for i in range(lo, hi):
        c = rows[i]
        com = centre_of_mass_row(positions[position_rows[i]], masses[c], com_fraction[c])
        out[c, 0], out[c, 1], out[c, 2] = com


@jit(nogil=True)
def com_and_error_rows(lo: int, hi: int, rows: I64, positions: F64, masses: F64,
                       com_fraction: F64, desired: F64, com: F64, error: F64) -> None:
    """COMControl's pass, for ``i`` in ``lo..hi-1``: the centre of mass of the posture
    ``positions[i]`` ((r, N_JOINTS, 3), m) of store row ``c = rows[i]`` on its segments
    (:func:`centres_of_mass`) into ``com[c]`` ((n, 3), m), and its horizontal distance (m)
    from ``desired[c]`` ((n, 3)) into ``error[c]`` ((n,); ``np.linalg.norm`` of the x, y
    difference), in one pass."""
    for i in range(lo, hi):
        c = rows[i]
        com[c, 0], com[c, 1], com[c, 2] = centre_of_mass_row(positions[i], masses[c],
                                                             com_fraction[c])
        dx, dy = com[c, 0] - desired[c, 0], com[c, 1] - desired[c, 1]
        error[c] = math.sqrt(dx * dx + dy * dy)


@jit(nogil=True)
def motion_rows(lo: int, hi: int, positions: F64, copy: F64, masses: F64, com_fraction: F64,
                centres: F64, pose: PoseArrays, packed: F64, last_values: F64, fresh: B8,
                pack: bool) -> None:
    """ConstraintSolve's pass over the motion's pose of the tick, rows ``lo..hi-1``, each row
    read once: its joints ``positions`` (n, N_JOINTS, 3) copied into ``copy``; its centre of
    mass into ``centres`` (n, 3) where its pelvis is finite (:func:`centres_of_mass` on its
    ``masses`` and ``com_fraction``), else NaN (a row not decoded); with ``pack``, its values
    of ``pose`` packed into ``packed`` (n, N_VALUES; as
    :func:`ecs_anim.runtime.kernels.joint_speed.pack_rows`) and whether its last values
    ``last_values`` (n, N_VALUES) are none (their first quaternion all zeros) into ``fresh``
    (n,)."""
    for c in range(lo, hi):
        copy_row(copy, c, positions, c)
        if math.isfinite(positions[c, 0, 0]):
            com = centre_of_mass_row(positions[c], masses[c], com_fraction[c])
            centres[c, 0], centres[c, 1], centres[c, 2] = com
        else:
            centres[c, 0] = centres[c, 1] = centres[c, 2] = math.nan
        if pack:
            pack_row(pose, c, packed)
            fresh[c] = (last_values[c, 0] == 0.0 and last_values[c, 1] == 0.0
                        and last_values[c, 2] == 0.0 and last_values[c, 3] == 0.0)


class Motion(NamedTuple):
    """What :func:`motion_of` gives: the motion's joints copied (n, N_JOINTS, 3), its centres
    of mass (n, 3; NaN for a row not decoded), its values packed (n, N_VALUES; None unless
    asked) and the rows with no last values (n,; None likewise)."""

    positions: F64
    centres: F64
    packed: F64 | None
    fresh: B8 | None


def motion_of(positions: F64, poses: NormalizedPoses, masses: F64, com_fraction: F64,
              last_values: F64, pack: bool) -> Motion:
    """:class:`Motion` of the decoded motion ``positions`` (n, N_JOINTS, 3, NaN rows: not
    decoded) and its pose ``poses`` (n,), in one pass (:func:`motion_rows`): the same as
    ``positions.copy()``, ConstraintSolve's compiled centres of mass of the finite rows,
    :func:`ecs_anim.runtime.kernels.joint_speed.pack` and ``~np.any(last_values[:, :4] != 0,
    axis=1)`` (``last_values`` (n, N_VALUES), read with ``pack`` only)."""
    n = positions.shape[0]
    positions = np.ascontiguousarray(positions, dtype=np.float64)
    copy, centres = np.empty_like(positions), np.empty((n, 3))
    pose = pose_arrays(poses)
    if pack and last_values.shape == (n, N_VALUES):
        packed, fresh = np.empty((n, N_VALUES)), np.empty(n, np.bool_)
        last = np.ascontiguousarray(last_values, dtype=np.float64)
    else:
        packed, fresh = np.empty((0, N_VALUES)), np.empty(0, np.bool_)
        last = np.empty((0, N_VALUES))
    over_chunks(motion_rows, n, positions, copy, np.ascontiguousarray(masses, dtype=np.float64),
                np.ascontiguousarray(com_fraction, dtype=np.float64), centres, pose, packed, last,
                fresh, bool(fresh.size == n and n > 0))
    if not pack:
        return Motion(copy, centres, None, None)
    if fresh.size != n:  # (the last values of other rows: as numpy, which fails on them)
        packed = np.empty((n, N_VALUES))
        over_chunks(pack_rows, n, np.arange(n, dtype=np.int64), pose, packed)
        first = last_values[:, :4]
        fresh = ((first[:, 0] == 0.0) & (first[:, 1] == 0.0) & (first[:, 2] == 0.0)
                 & (first[:, 3] == 0.0))
    return Motion(copy, centres, packed, fresh)
