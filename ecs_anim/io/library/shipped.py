"""The project's own small motion library, authored procedurally (no captured data).

``python -m ecs_anim.io.library [--check]`` writes (or checks) ``scenarios/motions/*.bvh``: the
walk, run and idle of :mod:`ecs_anim.io.library.authoring` and the keyframed gestures of
:mod:`ecs_anim.io.library.gestures` (guard, kick, ward_off_punch, dodge, talk, reach, dance); the
shipped files are exactly what these generators produce, and a test keeps it so.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.morphology import Morphology
from ecs_anim.core.normalized import NormalizedPoses, decode, encode, frames_from_positions
from ecs_anim.io.export.bvh import bvh_text
from ecs_anim.io.library.authoring import FPS, GENERATORS
from ecs_anim.io.library.gestures import GESTURE_GENERATORS

F64 = NDArray[np.float64]

#: Where the shipped clips live: ``scenarios/motions`` at the repository's root.
MOTIONS_DIR = Path(__file__).resolve().parents[3] / "scenarios" / "motions"


def shipped_motion_paths() -> list[Path]:
    """The shipped clips' BVH files, sorted."""
    return sorted(MOTIONS_DIR.glob("*.bvh"))


def all_generators() -> dict[str, Callable[[Morphology], F64]]:
    """Every authored motion: the walk, run and idle of :mod:`.authoring`, the gestures of
    :mod:`.gestures`."""
    return {**GENERATORS, **GESTURE_GENERATORS}


def authored_poses(name: str, morph: Morphology) -> NormalizedPoses:
    positions = all_generators()[name](morph)
    return encode(positions, *frames_from_positions(positions), morph.lengths)


def authored_bvh_text(name: str) -> str:
    """The shipped BVH of an authored motion, played on the ``adult_male`` body."""
    morph = Morphology.preset("adult_male")
    poses = authored_poses(name, morph)
    return bvh_text(decode(poses, morph.lengths), morph, FPS)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ecs_anim.io.library",
                                     description="write or check the authored motion library")
    parser.add_argument("--check", action="store_true", help="only compare with the shipped files")
    args = parser.parse_args(argv)
    stale = []
    for name in all_generators():
        path = MOTIONS_DIR / f"{name}.bvh"
        text = authored_bvh_text(name)
        if args.check:
            if not path.exists() or path.read_text() != text:
                stale.append(str(path))
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text)
            print(f"wrote {path}")
    if stale:
        print(f"out of date: {', '.join(stale)} (run python -m ecs_anim.io.library)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
