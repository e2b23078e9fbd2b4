"""Joint centres under construction and the markers they come from: markers by role, the
centres placed so far with how each was placed, and the body's leg length with adult segment
lengths scaled to it."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.morphology import ADULT_PROPORTIONS
from ecs_anim.core.rotations import rot_axis, yaw_of
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import REST_HIP_DIR_LEFT

F64 = NDArray[np.float64]
BOOL = NDArray[np.bool_]

#: Marker radius (m) where the file stores no marker diameter.
MARKER_RADIUS_M = 0.007
#: An adult's leg (thigh and shank) in :data:`~ecs_anim.core.morphology.ADULT_PROPORTIONS`' units.
ADULT_LEG_PROPORTION = ADULT_PROPORTIONS["thigh"] + ADULT_PROPORTIONS["shank"]


def adult_length(name: str, leg_m: float) -> float:
    """An adult segment length for a body of the given leg length (m)."""
    return ADULT_PROPORTIONS[name] / ADULT_LEG_PROPORTION * leg_m


@dataclass
class MarkersByRole:
    """Marker access by role after gap filling, metres, Z up."""

    points: F64  # (F, M, 3)
    #: (F, M): in a long gap or held at an end (:func:`~ecs_anim.io.c3d.repair.fill_gaps`).
    unreliable: BOOL
    found: dict[str, int]
    #: The subject's measurements stored in the file
    #: (:data:`~ecs_anim.io.c3d.reading.ANTHROPOMETRY`), metres.
    anthropometry: dict[str, float] = field(default_factory=dict)
    #: The lab's gait model the file names (:attr:`~ecs_anim.io.c3d.reading.C3dMarkers.lab_model`).
    lab_model: str = ""

    def marker_radius(self) -> float:
        """Metres: half the file's marker diameter, else :data:`MARKER_RADIUS_M`."""
        return 0.5 * self.anthropometry["marker_diameter"] if "marker_diameter" in self.anthropometry \
            else MARKER_RADIUS_M

    def __call__(self, role: str) -> F64:
        return self.points[:, self.found[role]]

    def has(self, *roles: str) -> bool:
        return all(r in self.found for r in roles)


@dataclass
class JointCentreBuild:
    """The joint centres placed so far: positions (F, N_JOINTS, 3) metres, Z up; measured
    (N_JOINTS,) True where the markers place the joint; how each was placed; the pelvis, thorax
    and head frames (F, 3, 3) once known."""

    positions: F64
    measured: BOOL
    how: dict[str, str] = field(default_factory=dict)
    pelvis2world: F64 | None = None
    thorax2world: F64 | None = None
    head2world: F64 | None = None
    #: (F,) frames whose pelvis frame the markers determine (None: all of them).
    root_trusted: BOOL | None = None


def set_joint(build: JointCentreBuild, joint: str, value: F64, how: str) -> None:
    """Place ``joint`` at ``value`` (F, 3) in every frame, measured, saying ``how``."""
    build.positions[:, J[joint]] = value
    build.measured[J[joint]] = True
    build.how[joint] = how


def heading_frame(pelvis2world: F64) -> F64:
    """The upright frame (..., 3, 3) turned to a frame's heading (its yaw about Z)."""
    return rot_axis(2, yaw_of(pelvis2world))


def leg_length(build: JointCentreBuild, present: list[str]) -> float:
    """The body's leg length (m): hip-knee-ankle of the present legs (median over frames); with
    no leg, from the spine or the hip width at adult proportions."""
    p = build.positions
    legs = [s for s in "lr" if f"leg_{s}" in present]
    if legs:
        return float(np.mean([np.median(np.linalg.norm(p[:, J[f"knee_{s}"]] - p[:, J[f"hip_{s}"]], axis=-1)
                                        + np.linalg.norm(p[:, J[f"ankle_{s}"]] - p[:, J[f"knee_{s}"]], axis=-1))
                              for s in legs]))
    if "trunk" in present:
        spine = np.median(np.linalg.norm(p[:, J["neck"]] - p[:, J["pelvis"]], axis=-1))
        return float(spine / sum(ADULT_PROPORTIONS[k] for k in ("spine_lower", "spine_middle",
                                                                  "spine_upper")) * ADULT_LEG_PROPORTION)
    width = np.median(np.linalg.norm(p[:, J["hip_l"]] - p[:, J["hip_r"]], axis=-1))
    return float(width / (2 * ADULT_PROPORTIONS["pelvis"] * REST_HIP_DIR_LEFT[1]) * ADULT_LEG_PROPORTION)
