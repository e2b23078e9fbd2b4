"""Joint centres from a cluster marker set (technical clusters, no landmarks).

Each cluster's pose by a weighted least-squares rigid fit (Kabsch) to its mean shape
(:func:`~ecs_anim.io.c3d.centre_kernels.cluster_poses`); hips, knees and ankles by SCoRE
(:func:`~ecs_anim.io.c3d.centre_kernels.score_centre`; Ehrig et al. 2006, J Biomech 39:2798),
the centre of rotation that is fixed in both adjacent segments; knees and ankles move nearly as
hinges, whose centre is only defined up to a point on the axis, so the point on the axis nearest
the proximal joint centre is taken. A walk flexes the hips about
one axis too: there the hip is placed on its axis half an adult inter-hip distance (175 mm per
0.8 m of leg) from the pelvis cluster's mid-plane (the pelvis clusters here straddle it). On
such a hinge SCoRE's axis direction depends on the segment rotations only, but its location
also on the clusters' soft-tissue sliding (60 mm too high on a treadmill run); where the greater
trochanter is marked (``LGT``), the axis is moved to pass through it: the trochanter lies on the
hip's lateral axis at the femoral head centre's level (on average 3.4 mm above it, range -10 to
+20 mm: Theivendran & Hart 2009, Acta Orthop Belg 75(4)). The toe hangs a foot length
(adult proportions of the measured leg) in front of the ankle in the foot cluster's frame.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.rotations import frame_from_axes, normalize
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.c3d.centre_build import (
    JointCentreBuild,
    MarkersByRole,
    adult_length,
    leg_length,
    set_joint,
)
from ecs_anim.io.c3d.centre_kernels import cluster_poses, midpoint, score_centre
from ecs_anim.io.c3d.marker_sets import MarkerMap
from ecs_anim.io.importing import ankle_height_or_typical

F64 = NDArray[np.float64]
BOOL = NDArray[np.bool_]


#: Half the distance between the hip centres of an adult (about 175 mm for a 0.8 m leg), per m
#: of leg: where a trial moves the hips about one axis only, SCoRE cannot place them along it.
HALF_HIP_DISTANCE_PER_LEG = 0.0875 / 0.80


def cluster_key(role: str) -> str:
    """The rigid cluster a functional set's role belongs to (``THIGH_2_l`` -> ``THIGH_l``)."""
    parts = role.split("_")
    return parts[0] + ("_" + parts[2] if len(parts) > 2 else "")


def cluster_markers(mmap: MarkerMap) -> list[list[int]]:
    """Marker indices of each rigid cluster of a functional marker set (by role prefix)."""
    groups: dict[str, list[int]] = {}
    for role, i in mmap.marker.items():
        groups.setdefault(cluster_key(role), []).append(i)
    return [g for g in groups.values() if len(g) >= 3]


def functional_lower_body(mk: MarkersByRole, present: list[str], build: JointCentreBuild) -> None:
    """Place the pelvis, hips, knees, ankles and toes from the pelvis, thigh, shank and foot
    clusters, in ``build``."""
    def cluster(prefix: str, side: str | None, count: int) -> tuple[F64, F64, BOOL]:
        roles = [f"{prefix}_{k}" + (f"_{side}" if side else "") for k in range(1, count + 1)]
        idx = [mk.found[r] for r in roles]
        weights = (~mk.unreliable[:, idx]).astype(np.float64)
        rot, origin = cluster_poses(mk.points[:, idx], weights)
        return rot, origin, weights.sum(axis=1) >= 3

    pelvis_rot, pelvis_origin, pelvis_ok = cluster("PELVIS", None, 4)
    segments = {s: (cluster("THIGH", s, 4), cluster("SHANK", s, 4), cluster("FOOT", s, 3))
                for s in "lr" if f"leg_{s}" in present}
    # The pelvis frame's lateral axis joins the hips, which ride on the pelvis and thigh clusters.
    build.root_trusted = pelvis_ok & np.all([thigh[2] for thigh, _, _ in segments.values()], axis=0)
    # The pelvis cluster's left, from the thigh clusters (in the pelvis cluster's frame).
    lateral = np.zeros(3)
    if len(segments) == 2:
        between = segments["l"][0][1] - segments["r"][0][1]
        lateral = normalize(np.einsum("fji,fj->i", pelvis_rot, between))
    leg = 0.8
    for _ in range(2):  # the hip's lateral placement scales with the leg, measured in pass 1
        for s, (thigh, shank, foot) in segments.items():
            use = pelvis_ok & thigh[2]
            side = 1.0 if s == "l" else -1.0
            plane = (side * lateral, HALF_HIP_DISTANCE_PER_LEG * leg) if lateral.any() else None
            trochanter = None
            if mk.has(f"TROCHANTER_{s}"):  # the greater trochanter, in the pelvis cluster's frame
                trochanter = np.mean(np.einsum("fji,fj->fi", pelvis_rot[use],
                                               (mk(f"TROCHANTER_{s}") - pelvis_origin)[use]), axis=0)
            _, hip_in_thigh, hip = score_centre((pelvis_rot, pelvis_origin), thigh[:2], use,
                                                hinge_plane_in_parent=plane,
                                                hinge_through_in_parent=trochanter)
            set_joint(build, f"hip_{s}", hip, "SCoRE (Ehrig 2006), pelvis and thigh clusters; "
                      f"a flexion-only hip placed {HALF_HIP_DISTANCE_PER_LEG * leg * 1000:.0f} mm "
                      "from the pelvis cluster's mid-plane"
                      + (" on the axis through the greater trochanter" if trochanter is not None else ""))
            _, knee_in_shank, knee = score_centre(thigh[:2], shank[:2], thigh[2] & shank[2],
                                                  hip_in_thigh)
            set_joint(build, f"knee_{s}", knee, "SCoRE thigh/shank, point of the axis nearest the hip")
            _, _, ankle = score_centre(shank[:2], foot[:2], shank[2] & foot[2], knee_in_shank)
            set_joint(build, f"ankle_{s}", ankle, "SCoRE shank/foot, point of the axis nearest the knee")
        leg = leg_length(build, present)
    # Pelvis: between the hips; tilt and roll from the pelvis cluster.
    if "leg_l" in present and "leg_r" in present:
        hip_l, hip_r = build.positions[:, J["hip_l"]], build.positions[:, J["hip_r"]]
        set_joint(build, "pelvis", midpoint(hip_l, hip_r), "midpoint of the hip centres")
        up_local = normalize(np.einsum("fji,j->i", pelvis_rot, np.array([0.0, 0.0, 1.0])))
        build.pelvis2world = frame_from_axes(hip_l - hip_r, pelvis_rot @ up_local, 1, 2)
    else:
        raise EcsAnimError("a cluster marker set needs both leg clusters to place the pelvis "
                           f"(found {', '.join(present)})")
    leg = leg_length(build, present)
    forward = build.pelvis2world[..., :, 0]
    forward_h = normalize(forward * np.array([1.0, 1.0, 0.0]))
    foot_len = adult_length("foot", leg)
    for s in "lr":
        # The foot's stance orientation (the slowest third of the frames): the toe (ball of the
        # foot) lies a foot length forward of the ankle and on the floor (z = 0) there.
        foot_rot, foot_origin, foot_seen = cluster("FOOT", s, 3)
        ankle = build.positions[:, J[f"ankle_{s}"]]
        speed = np.linalg.norm(np.gradient(foot_origin, axis=0), axis=-1)
        # Only frames whose pelvis frame (the forward) and foot cluster are trusted: where the
        # pelvis cluster is half seen its frame can be upside down.
        usable = build.root_trusted & foot_seen
        if not usable.any():
            usable = np.ones_like(usable)
        stance = usable & (speed <= np.percentile(speed[usable], 33))
        up_local = normalize(np.einsum("fji,j->i", foot_rot[stance], np.array([0.0, 0.0, 1.0])))
        fwd_local = np.einsum("fji,fj->i", foot_rot[stance], forward_h[stance])
        fwd_local = normalize(fwd_local - (fwd_local @ up_local) * up_local)
        stance_height = float(np.median(ankle[stance, 2]))
        height = ankle_height_or_typical(stance_height, leg)
        drop = math.asin(float(np.clip(height / foot_len, 0.0, 0.85)))
        toe_local = foot_len * (math.cos(drop) * fwd_local - math.sin(drop) * up_local)
        level = "on the floor at stance" if height == stance_height else \
            f"an adult's ankle height ({height * 1000:.0f} mm) below the ankle at stance (the floor is not at z = 0)"
        set_joint(build, f"toe_{s}", ankle + foot_rot @ toe_local,
                  f"a foot length ({foot_len * 1000:.0f} mm) forward of the ankle, {level}")
        build.measured[J[f"toe_{s}"]] = False
