"""Every joint's centre from the markers: by the marker set's method (:mod:`.landmarks` or
:mod:`.clusters`), on the frames kept (:mod:`.trimming`), absent body parts in a neutral pose."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import N_JOINTS, REST_HIP_DIR_LEFT
from ecs_anim.io.c3d.centre_build import (
    JointCentreBuild,
    MarkersByRole,
    adult_length,
    heading_frame,
    leg_length,
)
from ecs_anim.io.c3d.clusters import functional_lower_body
from ecs_anim.io.c3d.landmarks import landmark_body
from ecs_anim.io.c3d.marker_sets import MarkerMap
from ecs_anim.io.c3d.trimming import kept_frames, parts_placed, trust_root

F64 = NDArray[np.float64]


def joint_centres(mk: MarkersByRole, mmap: MarkerMap, present: list[str]
                  ) -> tuple[JointCentreBuild, slice, slice, list[list[int]]]:
    """Joint centres and frames of every frame kept, with
    :func:`~ecs_anim.io.c3d.trimming.kept_frames`' slices (the pelvis' span, the frames kept)
    and :func:`~ecs_anim.io.c3d.trimming.trust_root`'s repaired runs; absent parts are filled on
    the trusted pelvis frame."""
    n = mk.points.shape[0]
    build = JointCentreBuild(np.zeros((n, N_JOINTS, 3)), np.zeros(N_JOINTS, dtype=bool))
    if mmap.preset.method == "functional":
        functional_lower_body(mk, present, build)
    else:
        landmark_body(mk, present, build)
    root, kept = kept_frames(build.root_trusted, parts_placed(mk, mmap, present), n)
    repaired = trust_root(build, kept)
    fill_absent(build, present)
    return build, root, kept, repaired


def flat_toe(ankle: F64, heading: F64, leg: float) -> F64:
    """The toe (n_frames, 3) of a foot lying flat the way ``heading`` (n_frames, 3, 3: an
    upright frame) faces, from its ``ankle`` (n_frames, 3): adult proportions of ``leg`` (m)."""
    up = np.array([0.0, 0.0, 1.0])
    toe: F64 = ankle + heading[..., :, 0] * adult_length("foot", leg) * 0.95 \
        - up * adult_length("ankle_height", leg)
    return toe


def fill_absent(build: JointCentreBuild, present: list[str]) -> None:
    """Neutral pose for absent body parts (upright trunk and head, arms hanging, legs straight),
    adult proportions of the measured leg length. Also spine_1/spine_2 and hand ends that the
    markers do not give."""
    p = build.positions
    assert build.pelvis2world is not None
    leg = leg_length(build, present)
    heading = heading_frame(build.pelvis2world)
    up = np.array([0.0, 0.0, 1.0])
    pelvis = p[:, J["pelvis"]]
    for s, sign in (("l", 1.0), ("r", -1.0)):
        if f"leg_{s}" in present:
            continue
        if not build.measured[J[f"hip_{s}"]]:
            x, y, z = REST_HIP_DIR_LEFT
            p[:, J[f"hip_{s}"]] = pelvis + build.pelvis2world @ (np.array([x, sign * y, z]) * adult_length("pelvis", leg))
        p[:, J[f"knee_{s}"]] = p[:, J[f"hip_{s}"]] - up * adult_length("thigh", leg)
        p[:, J[f"ankle_{s}"]] = p[:, J[f"knee_{s}"]] - up * adult_length("shank", leg)
        p[:, J[f"toe_{s}"]] = flat_toe(p[:, J[f"ankle_{s}"]], heading, leg)
    if "trunk" not in present:
        p[:, J["spine_1"]] = pelvis + up * adult_length("spine_lower", leg)
        p[:, J["spine_2"]] = p[:, J["spine_1"]] + up * adult_length("spine_middle", leg)
        p[:, J["neck"]] = p[:, J["spine_2"]] + up * adult_length("spine_upper", leg)
        build.thorax2world = heading
    if "head" not in present:
        thorax_up = build.thorax2world[..., :, 2]  # type: ignore[index]
        p[:, J["head"]] = p[:, J["neck"]] + thorax_up * adult_length("neck", leg)
        p[:, J["head_top"]] = p[:, J["head"]] + thorax_up * adult_length("head", leg)
        build.head2world = build.thorax2world
    thorax = build.thorax2world
    for s, sign in (("l", 1.0), ("r", -1.0)):
        if f"arm_{s}" in present:
            continue
        p[:, J[f"shoulder_{s}"]] = p[:, J["neck"]] + sign * thorax[..., :, 1] * adult_length("clavicle", leg)  # type: ignore[index]
        p[:, J[f"elbow_{s}"]] = p[:, J[f"shoulder_{s}"]] - up * adult_length("upper_arm", leg)
        p[:, J[f"wrist_{s}"]] = p[:, J[f"elbow_{s}"]] - up * adult_length("forearm", leg)
        p[:, J[f"hand_{s}"]] = p[:, J[f"wrist_{s}"]] - up * adult_length("hand", leg)
