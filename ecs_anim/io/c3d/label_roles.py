"""Which of the file's markers plays which role: its labels (or descriptions) matched to a marker
set, and one label naming two markers of a landmark told apart by position."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import MappingError
from ecs_anim.io.c3d.marker_sets import MarkerMap, match_markers
from ecs_anim.io.c3d.reading import C3dMarkers

F64 = NDArray[np.float64]
BOOL = NDArray[np.bool_]


def match_labels(raw: C3dMarkers, map_spec: str | None, usable: list[bool]
                  ) -> tuple[MarkerMap, list[str]]:
    """The marker map and the labels it names: ``POINT:LABELS``, or, where they name no marker
    set (generic ``M001``, ``M002``, ...) and no ``--map`` is given, ``POINT:DESCRIPTIONS``
    (Cortex's ``R.Shoulder``, ``L.ASIS``). Raises the labels' :class:`MappingError`."""
    try:
        return match_markers(raw.labels, map_spec, usable), raw.labels
    except MappingError:
        if map_spec is not None or not any(raw.descriptions):
            raise
        try:
            mmap = match_markers(raw.descriptions, None, usable)
        except MappingError:
            pass
        else:
            mmap.how += " from POINT:DESCRIPTIONS (the labels name no marker set)"
            return mmap, raw.descriptions
        raise


#: Lateral landmark roles and their medial twins, which some labs label alike.
MEDIAL_TWIN = {"KNEE_LAT": "KNEE_MED", "ANKLE_LAT": "ANKLE_MED", "ELBOW_LAT": "ELBOW_MED"}


def split_same_label(mmap: MarkerMap, positions: F64, valid: BOOL) -> None:
    """Where one label names two markers of a lateral landmark (Cortex's Helen Hayes set writes
    ``RKNE`` for both femoral epicondyles and ``RANK`` for both malleoli; the descriptions say
    R.Knee / R.Knee.Medial), tell them apart by position, not by their order in the file: the
    medial one is the nearer to the other limb's markers of that landmark (median distance over
    the frames where all are seen), and it takes the medial role if the file has no marker for
    it. ``mmap.marker`` is updated in place. positions (F, M, 3) in file units; valid (F, M)."""
    for lateral_base, medial_base in MEDIAL_TWIN.items():
        for s, other in (("l", "r"), ("r", "l")):
            lateral, medial = f"{lateral_base}_{s}", f"{medial_base}_{s}"
            pair = mmap.same_label.get(lateral, [])
            if len(pair) != 2 or medial in mmap.marker or medial not in mmap.preset.roles:
                continue
            opposite = mmap.same_label.get(f"{lateral_base}_{other}") or \
                [mmap.marker[r] for r in (f"{lateral_base}_{other}",) if r in mmap.marker]
            if not opposite:
                continue
            both = valid[:, pair].all(axis=1) & valid[:, opposite].all(axis=1)
            if not both.any():
                continue
            across = positions[both][:, opposite].mean(axis=1)
            distance = [float(np.median(np.linalg.norm(positions[both, i] - across, axis=-1)))
                        for i in pair]
            mmap.marker[lateral], mmap.marker[medial] = pair[int(np.argmax(distance))], \
                pair[int(np.argmin(distance))]
