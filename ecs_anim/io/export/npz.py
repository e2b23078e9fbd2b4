"""Joint positions for analysis: the ``.npz`` every export writes beside its BVH and glTF."""

from __future__ import annotations

from typing import IO

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.skeleton import JOINTS


def write_npz(f: IO[bytes], positions: NDArray[np.float64], fps: float,
              contacts: NDArray[np.bool_]) -> None:
    """Joint positions for analysis, written to the binary file ``f``: ``positions`` (frames,
    joints, 3) metres world Z up, ``joints`` names, ``fps``, ``contacts`` (frames, 2) bool
    [left, right]."""
    np.savez_compressed(f, positions=positions, joints=np.array(JOINTS), fps=np.float64(fps),
                        contacts=contacts)
