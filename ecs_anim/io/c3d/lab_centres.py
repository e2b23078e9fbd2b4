"""Our hip, knee and ankle centres against those the lab's model stored in the file."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.c3d.marker_sets import MarkerMap

F64 = NDArray[np.float64]
BOOL = NDArray[np.bool_]


#: How labs store their own joint centres as points, per joint and side ({S}: L/R), compared
#: on label keys (:func:`~ecs_anim.io.c3d.marker_sets.label_key`): Vicon Plug-in Gait and pyCGM2
#: (``LHJC``, ``RKJC_CGM_2.4``: a key starting so), Motion Analysis Cortex virtual points
#: (``VRHI``, ``VLKN``, ``VRAN``) and BTS (``r hip``, ``l knee``, ``r ankle``: exact keys).
LAB_CENTRES = {
    "hip": (("{S}HJC", True), ("V{S}HI", False), ("{S}HIP", False)),
    "knee": (("{S}KJC", True), ("V{S}KN", False), ("{S}KNEE", False)),
    "ankle": (("{S}AJC", True), ("V{S}AN", False), ("{S}ANKLE", False)),
}


def lab_joint_centres(labels: list[str], points: F64, valid: BOOL, positions: F64,
                      mmap: MarkerMap, present: list[str]) -> dict[str, dict[str, Any]]:
    """Our hip, knee and ankle centres against the lab's stored ones (:data:`LAB_CENTRES`),
    per joint found: the lab's label, the median and 95th percentile of the distance (mm) over
    the frames where the lab's point holds a sample. Points the marker set uses as markers are
    never taken for centres; of two points with one label the one with most samples is.

    points (F, M, 3) all points, metres, Z up; valid (F, M); positions (F, N_JOINTS, 3)."""
    used = set(mmap.marker.values())
    keys = [mmap.keys.get(i, "") for i in range(len(labels))]
    out: dict[str, dict[str, Any]] = {}
    for joint, patterns in LAB_CENTRES.items():
        for side in "lr":
            if f"leg_{side}" not in present:
                continue
            for pattern, prefix in patterns:
                want = pattern.format(S=side.upper())
                found = [i for i, k in enumerate(keys) if i not in used and valid[:, i].any()
                         and (k.startswith(want) if prefix else k == want)]
                if found:
                    i = max(found, key=lambda m: int(valid[:, m].sum()))
                    ok = valid[:, i]
                    dist = np.linalg.norm(points[ok, i] - positions[ok, J[f"{joint}_{side}"]], axis=-1)
                    out[f"{joint}_{side}"] = {
                        "label": labels[i], "median_mm": round(float(np.median(dist)) * 1000, 1),
                        "p95_mm": round(float(np.percentile(dist, 95)) * 1000, 1),
                        "frames": int(ok.sum())}
                    break
    return out
