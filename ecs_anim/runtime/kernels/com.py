"""Compiled centre of mass (COMControl's work): de Leva segment masses over joint positions.

Mirrors :func:`ecs_anim.core.morphology.centres_of_mass`. The segments' joints
(:data:`ecs_anim.core.morphology.MASS_SEGMENTS`) are passed as index arrays (:func:`segment_joints`).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.morphology import MASS_SEGMENTS
from ecs_anim.core.skeleton import JOINT_INDEX
from ecs_anim.runtime.kernels.vec import F64, jit

I64 = NDArray[np.int64]


def segment_joints() -> tuple[I64, I64]:
    """Proximal and distal joint of each mass segment, (n_segments,) int64 each."""
    return (np.array([JOINT_INDEX[s[1]] for s in MASS_SEGMENTS], dtype=np.int64),
            np.array([JOINT_INDEX[s[2]] for s in MASS_SEGMENTS], dtype=np.int64))


@jit()
def centre_of_mass_row(p: F64, masses: F64, com_fraction: F64, proximal: I64,
                       distal: I64) -> tuple[float, float, float]:
    """Whole-body centre of mass of one posture ``p`` (N_JOINTS, 3) m, from its segments'
    ``masses`` (kg) and ``com_fraction`` (n_segments,) (mirrors one row of
    :func:`ecs_anim.core.morphology.centres_of_mass`)."""
    x = y = z = 0.0
    total = 0.0
    for s in range(proximal.shape[0]):
        a, b = proximal[s], distal[s]
        f, m = com_fraction[s], masses[s]
        x += m * (p[a, 0] + f * (p[b, 0] - p[a, 0]))
        y += m * (p[a, 1] + f * (p[b, 1] - p[a, 1]))
        z += m * (p[a, 2] + f * (p[b, 2] - p[a, 2]))
        total += m
    return (x / total, y / total, z / total)


@jit(nogil=True)
def centres_of_mass(lo: int, hi: int, rows: I64, position_rows: I64, positions: F64, masses: F64,
                    com_fraction: F64, proximal: I64, distal: I64, out: F64) -> None:
    """Mirrors :func:`ecs_anim.core.morphology.centres_of_mass` over the store rows ``rows`` (int64)
    ``rows[lo:hi]``: the centre of mass of the posture ``positions[position_rows[i]]``
    ((m, N_JOINTS, 3), m) of store row ``c = rows[i]`` on its segments ``masses[c]`` (kg) and
    ``com_fraction[c]`` ((n, n_segments) each) into ``out[c]`` ((n, 3), m). Pass ``rows`` as
    ``position_rows`` for positions held by store row, ``arange`` for gathered ones."""
    for i in range(lo, hi):
        c = rows[i]
        com = centre_of_mass_row(positions[position_rows[i]], masses[c], com_fraction[c],
                                 proximal, distal)
        out[c, 0], out[c, 1], out[c, 2] = com


@jit(nogil=True)
def horizontal_errors(lo: int, hi: int, rows: I64, com: F64, desired: F64, out: F64) -> None:
    """Horizontal distance (m) of ``com[c]`` from ``desired[c]`` ((n, 3) each) into ``out[c]``
    ((n,)) for the store rows ``c`` in ``rows`` (``np.linalg.norm`` of the x, y difference)."""
    for i in range(lo, hi):
        c = rows[i]
        dx, dy = com[c, 0] - desired[c, 0], com[c, 1] - desired[c, 1]
        out[c] = math.sqrt(dx * dx + dy * dy)
