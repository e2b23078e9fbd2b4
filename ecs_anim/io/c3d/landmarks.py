"""Joint centres from a landmark marker set (Plug-in Gait, ISB/CAST):

* hips: Harrington et al. 2007 (J Biomech 40:595) regression from pelvis width PW (ASIS-ASIS)
  and depth PD (mid-ASIS to mid-PSIS or sacrum), in the pelvis frame (mm):
  posterior 0.24 PD + 9.9, inferior 0.30 PW + 10.9, lateral 0.33 PW + 7.3; where the file
  stores the subject's leg length (Plug-in Gait's ``PROCESSING``, BTS's ``SUBJECT`` group:
  :data:`~ecs_anim.io.c3d.reading.ANTHROPOMETRY`), the lab's model on it
  (:func:`~ecs_anim.io.c3d.hip_models.lab_model_hip`): Davis et al. 1991 with the file's
  ASIS-trochanter distance, or Hara et al. 2016 where the file names pyCGM2's CGM 2.1 or later;
* knees / ankles: midpoint of the epicondyles / malleoli when both are marked; otherwise the
  Plug-in-Gait chord rule (Davis et al. 1991; Kadaba et al. 1990): the centre lies half a joint
  width plus a marker radius from the lateral marker, in the plane of the proximal joint
  centre, the lateral marker and the wand (THI / TIB), with the proximal segment perpendicular
  to the offset. The rule assumes the wand stands out along the flexion axis; where it lies
  more than :data:`WAND_MAX_ANGLE_DEG` off the axis (a technical marker in front of the thigh
  or shank, as Motion Analysis' Helen Hayes set and some Codamotion and Qualisys sets place
  it), the plane is that of the flexion axis itself: the normal of the hip-knee-ankle plane,
  averaged in the thigh frame over the most flexed frames (after the dynamic knee-axis calibration of
  pyCGM2's ``calibrate2dof``, "similar to DynaKAD", Baker, Finney & Orr 1999), or the
  epicondyle line where the medial epicondyle is marked;
* toes (ball of the foot): TOE (2nd metatarsal head) or the midpoint of MT1 and MT5;
* neck base: midpoint of C7 and the jugular notch (CLAV / IJ); mid-thorax: midpoint of
  T10 (T8) and the xiphoid (STRN / PX) when both are marked, otherwise interpolated;
* shoulders: 17 % of the acromion-acromion distance below the acromion marker (or the midpoint
  of a front and a back shoulder marker), along the thorax axis (after Rab et al. 2002);
* elbows: midpoint of the humeral epicondyles, or the lateral marker moved medially by half an
  elbow width plus a marker radius along the flexion axis (the normal of the shoulder-elbow-wrist
  plane, averaged in an upper-arm frame over the most flexed frames, so a straight arm keeps
  it: :func:`~ecs_anim.io.c3d.centre_kernels.flexion_axis`);
* wrists: midpoint of the radial and ulnar styloid markers (WRA/WRB); hand end: FIN or the
  midpoint of the 2nd and 5th metacarpal heads;
* head: the four head-band markers give the head frame (or a marker on each side of the head
  and one on the forehead or the back of the head: the sides' midpoint and the direction from
  the back or to the forehead); skull base and vertex lie half a head length below and above
  the markers' centre.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.morphology import ADULT_PROPORTIONS
from ecs_anim.core.rotations import frame_from_axes, normalize
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.c3d.centre_build import (
    ADULT_LEG_PROPORTION,
    MARKER_RADIUS_M,
    JointCentreBuild,
    MarkersByRole,
    adult_length,
    heading_frame,
    leg_length,
    set_joint,
)
from ecs_anim.io.c3d.centre_kernels import chord_centre, flexion_axis, midpoint
from ecs_anim.io.c3d.hip_models import lab_model_hip

F64 = NDArray[np.float64]
BOOL = NDArray[np.bool_]


#: Adult widths (m) for the chord rules, scaled by leg length / 0.8 m.
JOINT_WIDTH_PER_LEG = {"knee": 0.105 / 0.80, "ankle": 0.070 / 0.80, "elbow": 0.070 / 0.80}


#: A thigh or shank wand whose offset from the limb lies within this angle of the flexion axis
#: marks the chord rule's plane (Plug-in Gait, Davis 1991); further off, the axis itself does.
WAND_MAX_ANGLE_DEG = 45.0


#: Hip-knee-ankle plane normal -> knee and ankle centres -> plane normal again (converged by 3).
FLEXION_AXIS_ITERATIONS = 3


SHOULDER_DROP = 0.17  # of the acromion-acromion distance (Rab et al. 2002)


def _landmark_pelvis(mk: MarkersByRole, build: JointCentreBuild) -> None:
    # Pelvis (ISB-like frame: y along ASIS_r -> ASIS_l, x forward in the ASIS/PSIS plane).
    asis_l, asis_r = mk("ASIS_l"), mk("ASIS_r")
    back = midpoint(mk("PSIS_l"), mk("PSIS_r")) if mk.has("PSIS_l", "PSIS_r") else mk("SACRUM")
    back_name = "LPSI/RPSI" if mk.has("PSIS_l", "PSIS_r") else "SACR"
    front = midpoint(asis_l, asis_r)
    pelvis2world = frame_from_axes(asis_l - asis_r, front - back, 1, 0)
    roles = ["ASIS_l", "ASIS_r"] + (["PSIS_l", "PSIS_r"] if mk.has("PSIS_l", "PSIS_r") else ["SACRUM"])
    build.root_trusted = np.asarray(~mk.unreliable[:, [mk.found[r] for r in roles]].any(axis=1))
    width = float(np.median(np.linalg.norm(asis_l - asis_r, axis=-1)))
    depth = float(np.median(np.linalg.norm(front - back, axis=-1)))
    harrington = f"Harrington 2007 (PW {width * 1000:.0f} mm, PD {depth * 1000:.0f} mm, ASIS + {back_name})"
    for s, sign in (("l", 1.0), ("r", -1.0)):
        lab = lab_model_hip(mk.anthropometry, mk.lab_model, s, mk.marker_radius(), width)
        if lab is not None:
            local, how = lab
            local[1] *= sign
        else:
            local = np.array([-0.24 * depth - 0.0099, sign * (0.33 * width + 0.0073),
                              -0.30 * width - 0.0109])
            how = harrington
        set_joint(build, f"hip_{s}", front + pelvis2world @ local, how)
    set_joint(build, "pelvis", midpoint(build.positions[:, J["hip_l"]], build.positions[:, J["hip_r"]]),
              "midpoint of the hip centres")
    build.pelvis2world = pelvis2world


def _acromion(mk: MarkersByRole, s: str) -> F64:
    """The acromion of side ``s`` (F, 3): its marker, or the midpoint of the markers in front
    of it and behind it (MoSh's SehoonVSK FSH/BSH)."""
    if mk.has(f"ACROMION_{s}"):
        return mk(f"ACROMION_{s}")
    return midpoint(mk(f"SHOULDER_FRONT_{s}"), mk(f"SHOULDER_BACK_{s}"))


def _pelvis_under_trunk(mk: MarkersByRole, present: list[str], build: JointCentreBuild) -> None:
    """Upper-body trials: the pelvis (not marked) hangs a spine length below the neck base along
    the thorax axis, upright, facing the thorax' heading. The body's size comes from the
    acromion distance (two clavicles of adult proportions) when both arms are marked."""
    neck = midpoint(mk("C7"), mk("IJ"))
    if mk.has("T10", "PX"):
        axis = normalize(neck - midpoint(mk("T10"), mk("PX")))
    else:
        axis = np.broadcast_to(np.array([0.0, 0.0, 1.0]), neck.shape)
    thorax2world = frame_from_axes(axis, mk("IJ") - mk("C7"), 2, 0)
    roles = ["C7", "IJ"] + (["T10", "PX"] if mk.has("T10", "PX") else [])
    build.root_trusted = np.asarray(~mk.unreliable[:, [mk.found[r] for r in roles]].any(axis=1))
    if "arm_l" in present and "arm_r" in present:
        width = float(np.median(np.linalg.norm(_acromion(mk, "l") - _acromion(mk, "r"), axis=-1)))
        leg = width / (2 * ADULT_PROPORTIONS["clavicle"]) * ADULT_LEG_PROPORTION
    else:
        leg = 0.8
    spine = sum(adult_length(k, leg) for k in ("spine_lower", "spine_middle", "spine_upper"))
    build.positions[:, J["pelvis"]] = neck - spine * axis
    build.pelvis2world = heading_frame(thorax2world)
    build.how["pelvis"] = "not marked: a spine length below the neck base"


def landmark_body(mk: MarkersByRole, present: list[str], build: JointCentreBuild) -> None:
    """Place the present parts' joint centres and frames from a landmark set, in ``build``."""
    if "pelvis" in present:
        _landmark_pelvis(mk, build)
    else:
        _pelvis_under_trunk(mk, present, build)
    # Legs.
    leg_guess = _leg_guess_from_markers(mk, present, build)
    for s in "lr":
        if f"leg_{s}" not in present:
            continue
        _knee_and_ankle(mk, build, s, leg_guess)
        if mk.has(f"TOE_{s}"):
            set_joint(build, f"toe_{s}", mk(f"TOE_{s}"), "TOE marker (2nd metatarsal head)")
        else:
            set_joint(build, f"toe_{s}", midpoint(mk(f"MT1_{s}"), mk(f"MT5_{s}")), "midpoint of MT1 and MT5")
    # Trunk.
    if "trunk" in present:
        c7, ij = mk("C7"), mk("IJ")
        neck = midpoint(c7, ij)
        set_joint(build, "neck", neck, "midpoint of C7 and the jugular notch")
        pelvis = build.positions[:, J["pelvis"]]
        if mk.has("T10", "PX"):
            mid = midpoint(mk("T10"), mk("PX"))
            set_joint(build, "spine_2", mid, "midpoint of T10/T8 and the xiphoid")
            set_joint(build, "spine_1", midpoint(pelvis, mid), "")
            build.measured[J["spine_1"]] = False
            front, rear = midpoint(ij, mk("PX")), midpoint(c7, mk("T10"))
        else:
            mid = pelvis + (neck - pelvis) * (2 / 3)
            build.positions[:, J["spine_1"]] = pelvis + (neck - pelvis) / 3
            build.positions[:, J["spine_2"]] = mid
            front, rear = ij, c7
        build.thorax2world = frame_from_axes(neck - mid, front - rear, 2, 0)
    leg = leg_length(build, present)  # (with no legs, from the trunk: after it)
    # Arms.
    thorax = build.thorax2world
    acromion_width = None
    if "arm_l" in present and "arm_r" in present:
        acromion_width = float(np.median(np.linalg.norm(_acromion(mk, "l") - _acromion(mk, "r"), axis=-1)))
    for s, medial_sign in (("l", -1.0), ("r", 1.0)):
        if f"arm_{s}" not in present:
            continue
        down = -(thorax[..., :, 2] if thorax is not None else np.array([0.0, 0.0, 1.0]))
        aw = acromion_width if acromion_width is not None else 2 * adult_length("clavicle", leg) + 0.08
        shoulder = _acromion(mk, s) + SHOULDER_DROP * aw * down
        marked = "" if mk.has(f"ACROMION_{s}") else " (midway between the front and back shoulder markers)"
        set_joint(build, f"shoulder_{s}", shoulder,
                  f"{SHOULDER_DROP:.0%} of the acromion distance ({aw * 1000:.0f} mm) below the acromion{marked}")
        if mk.has(f"WRIST_RAD_{s}", f"WRIST_ULN_{s}"):
            wrist = midpoint(mk(f"WRIST_RAD_{s}"), mk(f"WRIST_ULN_{s}"))
            set_joint(build, f"wrist_{s}", wrist, "midpoint of the wrist markers")
        else:
            wrist = mk(f"WRIST_{s}")
            set_joint(build, f"wrist_{s}", wrist, "the wrist marker")
        lateral = mk(f"ELBOW_LAT_{s}")
        if mk.has(f"ELBOW_MED_{s}"):
            set_joint(build, f"elbow_{s}", midpoint(lateral, mk(f"ELBOW_MED_{s}")),
                      "midpoint of the humeral epicondyles")
        else:
            second = mk(f"UPPER_ARM_{s}") - lateral if mk.has(f"UPPER_ARM_{s}") else \
                np.broadcast_to(thorax[..., :, 0] if thorax is not None else [1.0, 0.0, 0.0], lateral.shape)
            medial = medial_sign * flexion_axis(shoulder, lateral, wrist, second)
            d = 0.5 * JOINT_WIDTH_PER_LEG["elbow"] * leg + MARKER_RADIUS_M
            set_joint(build, f"elbow_{s}", lateral + d * medial,
                      f"ELB moved {d * 1000:.0f} mm medially along the flexion axis")
        if mk.has(f"HAND_{s}"):
            set_joint(build, f"hand_{s}", mk(f"HAND_{s}"), "FIN marker")
        elif mk.has(f"MC2_{s}", f"MC5_{s}"):
            set_joint(build, f"hand_{s}", midpoint(mk(f"MC2_{s}"), mk(f"MC5_{s}")), "midpoint of MC2 and MC5")
        else:
            elbow = build.positions[:, J[f"elbow_{s}"]]
            build.positions[:, J[f"hand_{s}"]] = wrist + normalize(wrist - elbow) * adult_length("hand", leg)
    # Head.
    if "head" in present:
        if mk.has("HEAD_FRONT_l", "HEAD_FRONT_r", "HEAD_BACK_l", "HEAD_BACK_r"):
            fl, fr, bl, br = (mk(f"HEAD_{p}_{s}") for p, s in
                              (("FRONT", "l"), ("FRONT", "r"), ("BACK", "l"), ("BACK", "r")))
            centre = 0.25 * (fl + fr + bl + br)
            forward, left = midpoint(fl, fr) - midpoint(bl, br), midpoint(fl, bl) - midpoint(fr, br)
        else:  # a marker on each side of the head, level with the forehead's (or the back's)
            centre = midpoint(mk("HEAD_SIDE_l"), mk("HEAD_SIDE_r"))
            forward = mk("FOREHEAD") - centre if mk.has("FOREHEAD") else centre - mk("HEAD_REAR")
            left = mk("HEAD_SIDE_l") - mk("HEAD_SIDE_r")
        head2world = frame_from_axes(forward, left, 0, 1)
        half = 0.5 * adult_length("head", leg)
        set_joint(build, "head", centre - half * head2world[..., :, 2], "half a head length below the head markers' centre")
        set_joint(build, "head_top", centre + half * head2world[..., :, 2], "half a head length above it")
        build.head2world = head2world


def _knee_and_ankle(mk: MarkersByRole, build: JointCentreBuild, s: str, leg_guess: float) -> None:
    """Knee and ankle centres of leg ``s``: midpoints of the epicondyles / malleoli where both
    are marked; otherwise the chord rule, in the plane of the wand (THI / TIB) where the wand
    stands out laterally along the flexion axis (within :data:`WAND_MAX_ANGLE_DEG`, as Plug-in
    Gait and Davis 1991 place it), else in the plane of the flexion axis itself.

    The flexion axis is the epicondyle line where the medial epicondyle is marked; otherwise
    the normal of the hip-knee-ankle plane, averaged in the thigh frame (hip-knee, THI) over
    the frames that flex it (:func:`~ecs_anim.io.c3d.centre_kernels.flexion_axis`) and found by
    iterating from the hip-to-hip line: a wand in front of the thigh (a technical marker, as in
    Motion Analysis' Helen Hayes set) would put the centre behind the knee. The axis' sign: towards the other hip."""
    hip = build.positions[:, J[f"hip_{s}"]]
    towards_other_hip = build.positions[:, J[f"hip_{'r' if s == 'l' else 'l'}"]] - hip
    knee_lat, ankle_lat = mk(f"KNEE_LAT_{s}"), mk(f"ANKLE_LAT_{s}")
    d_knee = 0.5 * JOINT_WIDTH_PER_LEG["knee"] * leg_guess + mk.marker_radius()
    d_ankle = 0.5 * JOINT_WIDTH_PER_LEG["ankle"] * leg_guess + mk.marker_radius()
    roles = [f"{r}_{s}" for r in ("KNEE_LAT", "ANKLE_LAT", "THIGH") if f"{r}_{s}" in mk.found]
    use: BOOL = np.asarray(~mk.unreliable[:, [mk.found[r] for r in roles]].any(axis=1))
    if build.root_trusted is not None:
        use &= build.root_trusted
    if not use.any():  # nothing reliable: trust_root refuses the file or the gaps are reported
        use = np.ones_like(use)

    def wand_or_axis(proximal: F64, marker: F64, role: str, medial: F64, offset: float
                     ) -> tuple[F64, str]:
        """The chord-rule centre and how it was placed."""
        if mk.has(role):
            u = normalize(proximal - marker)
            w = mk(role) - marker
            off_line = normalize(w - np.sum(w * u, axis=-1, keepdims=True) * u)
            cos_lateral = float(np.median(np.sum(off_line * -medial, axis=-1)[use]))
            if cos_lateral >= math.cos(math.radians(WAND_MAX_ANGLE_DEG)):
                return chord_centre(proximal, mk(role), marker, offset), "the wand"
            angle = math.degrees(math.acos(max(-1.0, min(1.0, cos_lateral))))
            return chord_centre(proximal, marker - medial, marker, offset), \
                f"the flexion axis (the wand is {angle:.0f} deg off it)"
        return chord_centre(proximal, marker - medial, marker, offset), "the flexion axis"

    epicondyles = mk.has(f"KNEE_MED_{s}")
    if epicondyles:
        medial = normalize(mk(f"KNEE_MED_{s}") - knee_lat)
        iterations = 1
    else:
        medial = normalize(towards_other_hip)
        iterations = FLEXION_AXIS_ITERATIONS
    for step in range(iterations):
        if epicondyles:
            knee, knee_how = midpoint(knee_lat, mk(f"KNEE_MED_{s}")), "midpoint of the femoral epicondyles"
        else:
            knee, plane = wand_or_axis(hip, knee_lat, f"THIGH_{s}", medial, d_knee)
            knee_how = f"chord rule from hip and KNE in the plane of {plane} (offset {d_knee * 1000:.0f} mm)"
        if mk.has(f"ANKLE_MED_{s}"):
            ankle, ankle_how = midpoint(ankle_lat, mk(f"ANKLE_MED_{s}")), "midpoint of the malleoli"
        else:
            ankle, plane = wand_or_axis(knee, ankle_lat, f"SHANK_{s}", medial, d_ankle)
            ankle_how = f"chord rule from knee and ANK in the plane of {plane} (offset {d_ankle * 1000:.0f} mm)"
        if not epicondyles and step < iterations - 1:  # the axis for the next pass
            axis = flexion_axis(hip, knee, ankle, mk(f"THIGH_{s}") - knee, use)
            medial = axis * np.sign(np.median(np.sum(axis * towards_other_hip, axis=-1)[use]))
    set_joint(build, f"knee_{s}", knee, knee_how)
    set_joint(build, f"ankle_{s}", ankle, ankle_how)


def _leg_guess_from_markers(mk: MarkersByRole, present: list[str], build: JointCentreBuild) -> float:
    """Leg length (m) before knees and ankles are known: hip centre to lateral malleolus."""
    values = [np.median(np.linalg.norm(mk(f"ANKLE_LAT_{s}") - build.positions[:, J[f"hip_{s}"]], axis=-1))
              for s in "lr" if f"leg_{s}" in present]
    return float(np.mean(values)) if values else 0.8
