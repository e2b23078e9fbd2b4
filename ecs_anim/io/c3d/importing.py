"""From labelled C3D markers straight to a :class:`~ecs_anim.motion.clip.NormalizedMotion`.

read (the ``c3d`` package) -> match labels to a marker set (:mod:`ecs_anim.io.c3d.marker_sets`) ->
fill short gaps -> metres, Z up -> joint centres -> the same canonical clip, encoding, source
morphology and contact detection as BVH import (:func:`ecs_anim.io.importing.normalize_clip`).
No joint angle is ever computed: the representation is Cartesian.

Joint centres
-------------
Landmark sets (Plug-in Gait, ISB/CAST):

* hips: Harrington et al. 2007 (J Biomech 40:595) regression from pelvis width PW (ASIS-ASIS)
  and depth PD (mid-ASIS to mid-PSIS or sacrum), in the pelvis frame (mm):
  posterior 0.24 PD + 9.9, inferior 0.30 PW + 10.9, lateral 0.33 PW + 7.3; where the file
  stores the subject's leg length (Plug-in Gait's ``PROCESSING``, BTS's ``SUBJECT`` group:
  :data:`ANTHROPOMETRY`), the lab's model on it (:func:`lab_model_hip`): Davis et al. 1991 with
  the file's ASIS-trochanter distance, or Hara et al. 2016 where the file names pyCGM2's
  CGM 2.1 or later;
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
* shoulders: 17 % of the acromion-acromion distance below the acromion marker, along the thorax
  axis (after Rab et al. 2002);
* elbows: midpoint of the humeral epicondyles, or the lateral marker moved medially by half an
  elbow width plus a marker radius along the flexion axis (the normal of the shoulder-elbow-wrist
  plane, averaged in an upper-arm frame over the most flexed frames, so a straight arm keeps
  it: :func:`flexion_axis`);
* wrists: midpoint of the radial and ulnar styloid markers (WRA/WRB); hand end: FIN or the
  midpoint of the 2nd and 5th metacarpal heads;
* head: the four head-band markers give the head frame (or a marker on each side of the head
  and one on the forehead: their midpoint and the forehead's direction); skull base and vertex
  lie half a head length below and above the markers' centre.

Cluster sets (technical clusters, no landmarks): each cluster's pose by a weighted least-squares
rigid fit (Kabsch) to its mean shape; hips, knees and ankles by SCoRE (Ehrig et al. 2006,
J Biomech 39:2798), the centre of rotation that is fixed in both adjacent segments; knees and
ankles move nearly as hinges, whose centre is only defined up to a point on the axis, so the
point on the axis nearest the proximal joint centre is taken. A walk flexes the hips about
one axis too: there the hip is placed on its axis half an adult inter-hip distance (175 mm per
0.8 m of leg) from the pelvis cluster's mid-plane (the pelvis clusters here straddle it). On
such a hinge SCoRE's axis direction depends on the segment rotations only, but its location
also on the clusters' soft-tissue sliding (60 mm too high on a treadmill run); where the greater
trochanter is marked (``LGT``), the axis is moved to pass through it: the trochanter lies on the
hip's lateral axis at the femoral head centre's level (on average 3.4 mm above it, range -10 to
+20 mm: Theivendran & Hart 2009, Acta Orthop Belg 75(4)). The toe hangs a foot length
(adult proportions of the measured leg) in front of the ankle in the foot cluster's frame.

Joint centres whose bones change length by more than 15 % for at most ``MAX_GLITCH_S``
(0.05 s; marker swaps or ghost markers in fast motion) are replaced by interpolation and reported
(:func:`reject_joint_outliers`).

Gaps: a sample is invalid when its residual is negative, its coordinates are all zero or it is
not finite. Runs of at most ``max_gap`` frames (default :data:`DEFAULT_MAX_GAP_S` worth: 10
at 100 Hz, whatever the rate the same stretch of time) are interpolated linearly; longer
runs are interpolated as well (so no NaN ever reaches the output) and reported. Runs at the
trial's start or end are held from the nearest sample, so they are unreliable at any length:
the frames at the ends where a body part's own markers are missing are trimmed, with one line
each in ``info.parts_frames_trimmed`` (:func:`kept_frames`), as are those where the pelvis
markers are (:func:`trust_root`).
"""

from __future__ import annotations

import math
import os
import re
import struct
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import EcsAnimError, InputError, MappingError, listed, quoted
from ecs_anim.core.morphology import ADULT_PROPORTIONS
from ecs_anim.core.rotations import (
    frame_from_axes,
    matrix_from_quat,
    normalize,
    quat_from_matrix,
    rot_axis,
    slerp,
    yaw_of,
)
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import JOINTS, N_JOINTS, REST_HIP_DIR_LEFT
from ecs_anim.io.c3d.force_plates import (
    ForcePlate,
    PlateLayout,
    plate_contacts,
    plate_edges,
    plate_layout,
)
from ecs_anim.io.c3d.marker_sets import (
    GROUP_WORDS,
    GROUPS,
    MarkerMap,
    check_usable,
    match_markers,
    part_roles,
)
from ecs_anim.io.contacts import ContactThresholds, frames_of, gait_event_kind, true_runs
from ecs_anim.io.importing import (
    UNITS,
    UP_AXES,
    CanonicalClip,
    FrameRange,
    ankle_height_or_typical,
    detect_unit,
    event_agreement,
    leading_rest_frames,
    normalize_clip,
    trim_clip,
)
from ecs_anim.io.joint_map import JointMap
from ecs_anim.motion.clip import NormalizedMotion

F64 = NDArray[np.float64]
BOOL = NDArray[np.bool_]

#: Longest marker gap filled without a warning, in seconds (``--max-gap`` gives frames).
DEFAULT_MAX_GAP_S = 0.1
#: Adult widths (m) for the chord rules, scaled by leg length / 0.8 m; marker radius (m).
JOINT_WIDTH_PER_LEG = {"knee": 0.105 / 0.80, "ankle": 0.070 / 0.80, "elbow": 0.070 / 0.80}
MARKER_RADIUS_M = 0.007
C3D_BLOCK_BYTES = 512  # a C3D file is made of blocks of this size; its data ends padded to one
MAX_GLITCH_S = 0.05  # joint-centre outliers are replaced only in runs this short (seconds)
HINGE_RATIO = 0.2
#: ... and a hinge's axis runs across its segment (a knee's, an ankle's): the weakest direction
#: is taken for a hinge with a prior only when its cosine with the line from the free solution
#: to the prior (the proximal joint, up the segment) is below this (at least 60 degrees apart).
HINGE_ACROSS_COS = 0.5
#: A thigh or shank wand whose offset from the limb lies within this angle of the flexion axis
#: marks the chord rule's plane (Plug-in Gait, Davis 1991); further off, the axis itself does.
WAND_MAX_ANGLE_DEG = 45.0
#: A limb's plane gives its flexion axis in the frames flexed this much of the trial's most.
FLEXED_FRACTION = 0.7
#: Hip-knee-ankle plane normal -> knee and ankle centres -> plane normal again (converged by 3).
FLEXION_AXIS_ITERATIONS = 3
#: Half the distance between the hip centres of an adult (about 175 mm for a 0.8 m leg), per m
#: of leg: where a trial moves the hips about one axis only, SCoRE cannot place them along it.
HALF_HIP_DISTANCE_PER_LEG = 0.0875 / 0.80  # SCoRE: weakest / next eigenvalue below this = a hinge (axis undetermined)
SHOULDER_DROP = 0.17  # of the acromion-acromion distance (Rab et al. 2002)
_LEG_P = ADULT_PROPORTIONS["thigh"] + ADULT_PROPORTIONS["shank"]


def _prop(name: str, leg_m: float) -> float:
    """An adult segment length for a body of the given leg length (m)."""
    return ADULT_PROPORTIONS[name] / _LEG_P * leg_m


# --- reading -----------------------------------------------------------------------------------

@dataclass
class C3dMarkers:
    """Marker trajectories as read: file units and axes.

    positions : (n_frames, n_markers, 3); valid : (n_frames, n_markers) bool.
    """

    labels: list[str]
    positions: F64
    valid: BOOL
    rate: float
    units: str
    first_frame: int
    #: The ``EVENT`` group as stored: (label, context, time in seconds from the capture's start).
    events: list[tuple[str, str, float]] = field(default_factory=list)
    #: The subject's measurements stored with the trial (:data:`ANTHROPOMETRY`), metres.
    anthropometry: dict[str, float] = field(default_factory=dict)
    #: ``POINT:DESCRIPTIONS``, one per marker ('' where none).
    descriptions: list[str] = field(default_factory=list)
    #: The lab's gait model the file names (:func:`lab_model_named`), '' where none.
    lab_model: str = ""
    #: The force plates whose vertical signal was read (:mod:`ecs_anim.io.c3d.force_plates`).
    force_plates: list[ForcePlate] = field(default_factory=list)
    #: Why some or all of the file's force plates were not read, '' when none was left out.
    force_plate_note: str = ""


#: The subject's measurements labs store with a trial that place the hip, mm, as (group:
#: parameter names) per quantity ({S}: L/R, {SIDE}: LEFT/RIGHT), compared without case, spaces
#: or underscores: Vicon Plug-in Gait and pyCGM2 (``PROCESSING:LLegLength``,
#: ``InterAsisDistance``, ``LAsisTrocanterDistance``, ``MarkerDiameter``) and BTS's Davis
#: protocol (``SUBJECT:LEFT LEG``, ``PELVIS WIDTH``, ``LEFT PELVIS DEPTH``: the ASIS to greater
#: trochanter distance). With each, the range (mm) a value must lie in to be taken (0 is "not
#: measured" in Plug-in Gait). (Knee and ankle widths are stored too; the chord rule keeps
#: adult widths: BTS's own centres lie 15-19 mm beyond half its measured widths, larger markers
#: than the radius assumed, and the measured widths took its ankle 2 mm further from them.)
ANTHROPOMETRY: dict[str, tuple[tuple[str, ...], tuple[float, float]]] = {
    "leg_length_{s}": (("PROCESSING:{S}LEGLENGTH", "SUBJECT:{SIDE}LEG"), (400.0, 1300.0)),
    "asis_distance": (("PROCESSING:INTERASISDISTANCE", "SUBJECT:PELVISWIDTH"), (150.0, 450.0)),
    "asis_trochanter_{s}": (("PROCESSING:{S}ASISTROCANTERDISTANCE", "SUBJECT:{SIDE}PELVISDEPTH"),
                            (20.0, 200.0)),
    "marker_diameter": (("PROCESSING:MARKERDIAMETER",), (3.0, 40.0)),
}


def _read_anthropometry(reader: Any) -> dict[str, float]:
    """The :data:`ANTHROPOMETRY` a file holds, metres; a value out of its range, unreadable or
    not a single number is left out (so is a quantity no parameter gives)."""
    params: dict[str, Any] = {}
    for group_name in ("PROCESSING", "SUBJECT"):
        group = reader.get(group_name)
        if group is None:
            continue
        for name, param in group.param_items():
            params[f"{group_name}:{''.join(str(name).split()).replace('_', '').upper()}"] = param
    out: dict[str, float] = {}
    for pattern, (names, (low, high)) in ANTHROPOMETRY.items():
        for s, side in (("l", "LEFT"), ("r", "RIGHT")) if "{s}" in pattern else ((None, ""),):
            for name in names:
                param = params.get(name.format(S=(s or "").upper(), SIDE=side))
                value = _number(param) if param is not None else None
                if value is not None and low <= value <= high:
                    out[pattern.format(s=s)] = value / 1000.0
                    break
    return out


#: pyCGM2's Conventional Gait Model 2.1 and later (``SUBJECTS:MARKER_SETS``
#: ``pyCGM2-LowerLimb_CGM24``, outputs ``LHJC_CGM_2.4``): they place the hips by Hara 2016.
#: The name stands alone ("pyCGM2 3.5" is the program's version, "CGM2.10" no model) and the
#: minor version is one digit.
_CGM2_NAME = re.compile(r"(?<![A-Za-z])CGM[\s_.\-]*2[\s_.\-]*([1-9])(?!\d)", re.IGNORECASE)


def lab_model_named(texts: list[str]) -> str:
    """The gait model the lab ran, as a file's marker-set names or point labels say it:
    ``"CGM 2.4"`` for pyCGM2's CGM 2.1 and later, '' where none is named (Plug-in Gait writes
    its outputs without a model's name)."""
    for text in texts:
        match = _CGM2_NAME.search(text)
        if match:
            return f"CGM 2.{match.group(1)}"
    return ""


def _number(param: Any) -> float | None:
    """A parameter's single number (float or integer storage), None otherwise."""
    try:
        size, scalar = int(param.bytes_per_element), not param.dimensions
        if size == 4:
            values = np.atleast_1d(param.float_value if scalar else param.float_array)
        elif size == 2:
            values = np.atleast_1d(param.int16_value if scalar else param.int16_array)
        else:
            return None
    except (AssertionError, ValueError, TypeError, AttributeError, struct.error):
        return None
    return float(values[0]) if values.size == 1 and np.isfinite(values[0]) else None


def _read_events(reader: Any) -> list[tuple[str, str, float]]:
    """``EVENT:LABELS``, ``EVENT:CONTEXTS`` and ``EVENT:TIMES`` (minutes and seconds per event,
    C3D's convention) as (label, context, seconds); ``EVENT:USED`` is not trusted (often 0 or
    unreadable), the number of times is. An unreadable group gives no event."""
    group = reader.get("EVENT")
    if group is None or group.get("TIMES") is None:
        return []
    try:
        times = np.asarray(group.get("TIMES").float_array, dtype=np.float64).reshape(-1, 2)
    except (AssertionError, ValueError, TypeError):
        return []

    def texts(name: str) -> list[str]:
        param = group.get(name)
        if param is None:
            return []
        try:
            return [str(t).strip() for t in np.atleast_1d(param.string_array)]
        except (AssertionError, ValueError, TypeError):
            return []

    labels, contexts = texts("LABELS"), texts("CONTEXTS")
    out = []
    for k, (minutes, seconds) in enumerate(times):
        label = labels[k] if k < len(labels) else ""
        context = contexts[k] if k < len(contexts) else ""
        t = 60.0 * minutes + seconds
        if math.isfinite(t):
            out.append((label, context, float(t)))
    return out


def _point_texts(reader: Any, base: str) -> list[str]:
    """``POINT:LABELS`` (``base``) then ``LABELS2``, ``LABELS3``, ... (a parameter holds at
    most 255 entries; files with more points go on in the next), each without the spaces and
    NUL bytes that pad it."""
    labels: list[str] = []
    for name in (base, *(f"{base}{k}" for k in range(2, 100))):
        param = reader.get(f"POINT:{name}")
        if param is None:
            break
        labels += [str(s).replace("\x00", " ").strip() for s in np.atleast_1d(param.string_array)]
    return labels


def read_c3d(path: str | Path) -> C3dMarkers:
    """Read marker data with the ``c3d`` package. Raises :class:`InputError` on a damaged,
    truncated or unlabelled file."""
    import c3d

    path = str(path)
    try:
        f = open(path, "rb")
    except OSError as exc:
        raise InputError(path, f"cannot read file: {exc.strerror or exc}") from None
    with f, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            reader = c3d.Reader(f)
            n_points = int(reader.point_used)
            rate = float(reader.point_rate)
            if float(reader.point_scale) == 0.0:  # every sample would read 0: all "no sample"
                raise InputError(path, "POINT:SCALE is 0 (a damaged header): the samples cannot "
                                       "be scaled to lengths")
            expected = int(reader.last_frame) - int(reader.first_frame) + 1
            first = int(reader.first_frame)
            labels = _point_texts(reader, "LABELS")
            descriptions = _point_texts(reader, "DESCRIPTIONS")
            units_param = reader.get("POINT:UNITS")
            units = "" if units_param is None else \
                "".join(ch for ch in units_param.string_value.lower() if ch.isalpha())
            events = _read_events(reader)
            anthropometry = _read_anthropometry(reader)
            marker_sets = reader.get("SUBJECTS:MARKER_SETS")
            lab_model = lab_model_named(
                labels + ([] if marker_sets is None else
                          [str(t) for t in np.atleast_1d(marker_sets.string_array)]))
            analog_used = int(reader.analog_used)
            layout = plate_layout(reader, analog_used) if analog_used > 0 else PlateLayout([], [], [])
            data_start = (int(reader.header.data_block) - 1) * C3D_BLOCK_BYTES
            frames, data_end = [], data_start
            plate_channels = sorted({c for chans in layout.channels for c in chans})
            plate_samples: list[F64] = []  # (plate channels, analog samples per frame) a frame
            for _, points, analog in (reader.read_frames() if n_points > 0 else ()):
                frames.append(points[:, :4].astype(np.float64))
                if plate_channels:
                    plate_samples.append(analog[plate_channels])
                data_end = f.tell()  # here, not after the loop: the reader reads on at its end
            analog_rate = float(reader.analog_rate) if plate_channels else 0.0
            unread = os.fstat(f.fileno()).st_size - data_end
            frame_bytes = (data_end - data_start) / max(len(frames), 1)
        except InputError:
            raise
        except Exception as exc:  # the reader raises struct, value, index errors on bad bytes
            reason = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
            if isinstance(exc, AssertionError) and str(exc):
                reason = str(exc)  # the reader's own consistency checks, in plain words
            raise InputError(path, "not a readable C3D file (damaged or truncated?): "
                                   f"{quoted(reason, 100)}") from None
    if n_points <= 0:
        raise InputError(path, "the C3D file holds no marker (POINT:USED is 0)")
    if not (math.isfinite(rate) and 0.1 <= rate <= 100000):
        raise InputError(path, f"implausible point rate {rate:g} Hz in the C3D header")
    if not frames:
        raise InputError(path, f"the C3D file holds no frame of marker data (header says {expected}; "
                               "truncated?)")
    if len(frames) < expected:
        raise InputError(path, f"file ends after {len(frames)} of {expected} frames (truncated?)")
    if unread > C3D_BLOCK_BYTES and unread >= frame_bytes:
        # Writers pad the data to a whole block; more left over means the frame layout read is
        # not the file's (a POINT:USED below the markers stored shifts every frame: garbage).
        raise InputError(path, f"{unread} bytes of data follow the {expected} frames of "
                               f"{n_points} markers the header announces: POINT:USED or the "
                               "frame range is wrong (damaged file?)")
    labels = (labels + [""] * n_points)[:n_points]
    if not any(labels):
        raise InputError(path, "the markers have no labels (POINT:LABELS is missing or blank): "
                               "label them in the capture software first")
    data = np.stack(frames)
    positions = data[:, :, :3]
    finite = np.all(np.isfinite(positions), axis=-1)
    valid = finite & (data[:, :, 3] >= 0) & np.any(positions != 0, axis=-1)
    positions = np.where(finite[..., None], positions, 0.0)
    descriptions = (descriptions + [""] * n_points)[:n_points]
    plates: list[ForcePlate] = []
    plate_notes = [layout.note] if layout.note else []
    if plate_samples and math.isfinite(analog_rate) and analog_rate > 0:
        samples = np.concatenate(plate_samples, axis=1).astype(np.float64)  # (channels, samples)
        row = {c: k for k, c in enumerate(plate_channels)}
        for number, corners, chans in zip(layout.numbers, layout.corners, layout.channels, strict=True):
            signal = samples[[row[c] for c in chans]].sum(axis=0)
            if np.all(np.isfinite(signal)):
                plates.append(ForcePlate(number, corners, signal, analog_rate))
            else:
                plate_notes.append(f"plate {number}: its vertical signal holds non-finite samples")
    elif plate_samples:
        plate_notes.append(f"the analog rate {analog_rate:g} Hz is not usable: no plate read")
    return C3dMarkers(labels, positions, valid, rate, units, first, events, anthropometry,
                      descriptions, lab_model, plates, "; ".join(plate_notes))


# --- gaps --------------------------------------------------------------------------------------

def fill_gaps(positions: F64, valid: BOOL, max_gap: int) -> tuple[F64, BOOL]:
    """Interpolate invalid samples of each marker linearly (held at the clip's ends).

    positions (F, M, 3), valid (F, M). Returns (filled positions, ``unreliable``): True (F, M)
    on samples in runs of more than ``max_gap`` invalid frames (filled too, but a guess), on
    runs at the trial's start or end of any length (held from the nearest sample: nothing
    brackets them, so a moving marker is simply wrong there) and on markers never seen. The
    loop runs over markers and gaps, never over frames.
    """
    out = positions.copy()
    unreliable = np.zeros(valid.shape, dtype=bool)
    frames = np.arange(valid.shape[0])
    last = valid.shape[0] - 1
    for m in range(valid.shape[1]):
        ok = valid[:, m]
        if ok.all():
            continue
        if not ok.any():
            unreliable[:, m] = True
            continue
        bad = ~ok
        for axis in range(3):
            out[bad, m, axis] = np.interp(frames[bad], frames[ok], positions[ok, m, axis])
        for a, b in true_runs(bad):
            if b - a + 1 > max_gap or a == 0 or b == last:
                unreliable[a:b + 1, m] = True
    return out, unreliable


def cluster_outliers(points: F64, valid: BOOL, tolerance_m: float = 0.015,
                     tolerance_fraction: float = 0.1) -> BOOL:
    """Samples of a rigid cluster that break its shape (mislabelled or swapped markers).

    points (F, K, 3) metres, valid (F, K). A sample is an outlier when more than half of its
    distances to the cluster's other valid markers differ from their median over the trial by
    more than ``tolerance_m + tolerance_fraction * median``. Returns (F, K) bool.
    """
    k = points.shape[1]
    dist = np.linalg.norm(points[:, :, None] - points[:, None], axis=-1)  # (F, K, K)
    pair_ok = valid[:, :, None] & valid[:, None, :]
    median = np.array([[np.median(dist[pair_ok[:, a, b], a, b]) if pair_ok[:, a, b].any() else 0.0
                        for b in range(k)] for a in range(k)])
    off = np.abs(dist - median) > tolerance_m + tolerance_fraction * median
    bad_pairs = (off & pair_ok).sum(axis=2)
    pairs = np.maximum(pair_ok.sum(axis=2) - 1, 0)  # the diagonal counts itself
    out: BOOL = valid & (bad_pairs * 2 > pairs) & (pairs > 0)
    return out


# --- small geometric kernels (batched over frames) --------------------------------------------

def _mid(a: F64, b: F64) -> F64:
    return 0.5 * (a + b)


def chord_centre(proximal: F64, wand: F64, marker: F64, offset: F64 | float) -> F64:
    """Plug-in-Gait chord rule: the joint centre ``c`` at ``offset`` from ``marker``, in the
    plane of (proximal, wand, marker), with (proximal - c) perpendicular to (marker - c), on the
    side away from the wand. All (F, 3) -> (F, 3)."""
    u_vec = proximal - marker
    length = np.linalg.norm(u_vec, axis=-1, keepdims=True)
    u = u_vec / np.maximum(length, 1e-12)
    w = wand - marker
    v = -normalize(w - np.sum(w * u, axis=-1, keepdims=True) * u)
    off = np.asarray(offset, dtype=np.float64)
    off = off[..., None] if off.ndim else off
    cos_t = np.clip(off / np.maximum(length, 1e-12), 0.0, 1.0)
    sin_t = np.sqrt(1.0 - cos_t**2)
    centre: F64 = marker + off * (cos_t * u + sin_t * v)
    return centre


def flexion_axis(proximal: F64, joint: F64, distal: F64, segment_second: F64,
                 use: BOOL | None = None) -> F64:
    """A hinge's flexion axis (unit, world, (F, 3)) as the normal of the proximal-joint-distal
    plane, ``cross(proximal - joint, distal - joint)``, averaged in the proximal segment's frame
    (long axis joint -> proximal, ``segment_second`` a second direction fixed in the segment)
    over the most flexed of the frames ``use`` (F,) (all when None): those whose flexion sine
    is at least :data:`FLEXED_FRACTION` of its 95th percentile. Near straight, the plane is set
    by skin-marker noise and ab/adduction more than by flexion. All inputs (F, 3)."""
    upper, lower = proximal - joint, distal - joint
    flex = np.cross(upper, lower)
    sine = np.linalg.norm(flex, axis=-1) / np.maximum(
        np.linalg.norm(upper, axis=-1) * np.linalg.norm(lower, axis=-1), 1e-12)
    frames = np.ones(len(flex), dtype=bool) if use is None else use
    flexed = frames & (sine >= FLEXED_FRACTION * np.percentile(sine[frames], 95))
    segment2world = frame_from_axes(upper, segment_second, 2, 0)
    axis_local = normalize(np.einsum("fji,fj->i", segment2world[flexed], flex[flexed]))
    axis: F64 = np.einsum("fij,j->fi", segment2world, axis_local)
    return axis


def cluster_poses(points: F64, weights: F64, iterations: int = 2) -> tuple[F64, F64]:
    """Rigid poses of a marker cluster by weighted least squares (Kabsch), batched over frames.

    points (F, K, 3) world, weights (F, K) (0 for missing samples). The cluster's local shape is
    its mean shape (first the first fully seen frame, then refined ``iterations`` times).
    Returns (cluster2world (F, 3, 3), origin (F, 3)) with ``points ≈ R @ shape + origin``.
    """
    full = np.flatnonzero(weights.min(axis=1) > 0)
    if len(full):  # the fully seen frame whose shape is closest to the typical one
        dist = np.linalg.norm(points[full, :, None] - points[full, None], axis=-1)
        ref_frame = int(full[np.argmin(np.abs(dist - np.median(dist, axis=0)).sum(axis=(1, 2)))])
    else:
        ref_frame = int(np.argmax(weights.sum(axis=1)))
    shape = points[ref_frame] - points[ref_frame].mean(axis=0)
    w = weights[..., None]
    wsum = np.maximum(weights.sum(axis=1), 1e-12)[:, None]
    for _ in range(iterations + 1):
        c_ref = np.einsum("fk,ki->fi", weights, shape) / wsum
        c_cur = (w * points).sum(axis=1) / wsum
        a = shape[None] - c_ref[:, None]
        b = points - c_cur[:, None]
        h = np.einsum("fk,fki,fkj->fij", weights, a, b)
        u, _, vt = np.linalg.svd(h)
        d = np.sign(np.linalg.det(np.swapaxes(vt, -1, -2) @ np.swapaxes(u, -1, -2)))
        fix = np.ones(u.shape[:-1])
        fix[:, 2] = d
        rot = np.swapaxes(vt, -1, -2) @ (fix[:, :, None] * np.swapaxes(u, -1, -2))
        origin = c_cur - np.einsum("fij,fj->fi", rot, c_ref)
        local = np.einsum("fji,fkj->fki", rot, points - origin[:, None])  # R^T (p - o)
        shape = (w * local).sum(axis=0) / np.maximum(weights.sum(axis=0), 1e-12)[:, None]
        shape -= shape.mean(axis=0)
    return rot, origin


def score_centre(parent: tuple[F64, F64], child: tuple[F64, F64], use: BOOL,
                 hinge_prior_in_parent: F64 | None = None,
                 hinge_plane_in_parent: tuple[F64, float] | None = None,
                 hinge_through_in_parent: F64 | None = None) -> tuple[F64, F64, F64]:
    """SCoRE (Ehrig et al. 2006): the point fixed in both segments.

    parent, child : (rotation (F, 3, 3), origin (F, 3)) segment poses; use : (F,) frames to fit.
    For a hinge the point is only defined up to the axis: with ``hinge_prior_in_parent`` (3,),
    when the weakest direction of the normal equations is clearly weaker than the others (by
    :data:`HINGE_RATIO`) and runs across the segment (:data:`HINGE_ACROSS_COS`: along it, it is
    the segment's twist in a joint that is no hinge, and the point nearest the prior would slide
    up the segment), it is dropped from the least-squares solution and the point on it nearest
    the prior is taken; with ``hinge_plane_in_parent`` (unit direction d (3,), offset) instead,
    the point on it with ``d . centre = offset``. ``hinge_through_in_parent`` (3,): a point known
    to lie on the hinge's axis (a landmark on it); the axis keeps SCoRE's direction but passes
    through that point, and the child's centre is refitted to it. Returns (centre in parent
    frame (3,), in child frame (3,), world position (F, 3): the mean of both estimates).
    """
    rp, tp = parent
    rc, tc = child
    a = np.concatenate([rp, -rc], axis=-1)[use]  # (F, 3, 6)
    b = (tc - tp)[use]
    m = np.einsum("fki,fkj->ij", a, a)
    v = np.einsum("fki,fk->i", a, b)
    evals, evecs = np.linalg.eigh(m)
    keep = evals > 1e-9 * evals[-1]
    hinge = (hinge_prior_in_parent is not None or hinge_plane_in_parent is not None) \
        and evals[0] < HINGE_RATIO * evals[1]
    if hinge and hinge_prior_in_parent is not None and hinge_plane_in_parent is None:
        free = evecs @ np.where(keep, (evecs.T @ v) / np.where(keep, evals, 1.0), 0.0)
        up_segment = normalize(hinge_prior_in_parent - free[:3])
        hinge = abs(float(normalize(evecs[:3, 0]) @ up_segment)) < HINGE_ACROSS_COS
    if hinge:
        keep[0] = False
    coeff = np.where(keep, (evecs.T @ v) / np.where(keep, evals, 1.0), 0.0)
    x = evecs @ coeff
    if hinge:
        n = evecs[:, 0]
        n_p = n[:3]
        if hinge_through_in_parent is not None:  # the axis through the landmark, in both frames
            x[:3] = hinge_through_in_parent
            x[3:] = np.mean(np.einsum("fji,fj->fi", rc[use], np.einsum("fij,j->fi", rp[use], x[:3])
                                      + tp[use] - tc[use]), axis=0)
            n = np.concatenate([n_p, np.mean(np.einsum("fji,fj->fi", rc[use],
                                                       np.einsum("fij,j->fi", rp[use], n_p)), axis=0)])
        if hinge_plane_in_parent is not None:
            d, offset = hinge_plane_in_parent
            lam = (offset - float(d @ x[:3])) / float(d @ n_p) if abs(float(d @ n_p)) > 1e-6 else 0.0
        else:
            assert hinge_prior_in_parent is not None
            lam = float(n_p @ (hinge_prior_in_parent - x[:3])) / max(float(n_p @ n_p), 1e-12)
        x = x + lam * n
    c_parent, c_child = x[:3], x[3:]
    world = 0.5 * (np.einsum("fij,j->fi", rp, c_parent) + tp + np.einsum("fij,j->fi", rc, c_child) + tc)
    return c_parent, c_child, world


# --- the importer ------------------------------------------------------------------------------

@dataclass
class _Markers:
    """Marker access by role after gap filling, metres, Z up."""

    points: F64  # (F, M, 3)
    unreliable: BOOL  # (F, M): in a long gap or held at an end (:func:`fill_gaps`)
    found: dict[str, int]
    #: The subject's measurements stored in the file (:data:`ANTHROPOMETRY`), metres.
    anthropometry: dict[str, float] = field(default_factory=dict)
    #: The lab's gait model the file names (:attr:`C3dMarkers.lab_model`).
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
class _Build:
    positions: F64
    measured: BOOL
    how: dict[str, str] = field(default_factory=dict)
    pelvis2world: F64 | None = None
    thorax2world: F64 | None = None
    head2world: F64 | None = None
    #: (F,) frames whose pelvis frame the markers determine (None: all of them).
    root_trusted: BOOL | None = None


def _detect_up(mk: _Markers, present: list[str], mmap: MarkerMap) -> str:
    """The file's up axis: the axis along which the body is tallest in a typical frame (the
    median over frames of the markers' spread), pointing from the legs to the pelvis (or from
    the pelvis to the trunk, the trunk to the head, or the sternum's and spine's lower markers
    (PX, T10) to their upper ones (IJ, C7), when those are what is marked)."""
    used = sorted(set(mk.found.values()))  # not other objects' markers
    # Measured samples only: a marker held over a long gap (seen in one frame, say) stays where
    # it was while the body walks on, and would stretch the spread along the walk.
    body = np.where(mk.unreliable[:, used, None], np.nan, mk.points[:, used])
    seen = np.sum(~mk.unreliable[:, used], axis=1) >= 2
    if not seen.any():
        body, seen = mk.points[:, used], np.ones(len(body), dtype=bool)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns of a frame
        spread = np.median(np.nanmax(body[seen], axis=1) - np.nanmin(body[seen], axis=1), axis=0)
    axis = int(np.argmax(spread))
    groups = mmap.preset.groups

    def mean_of(roles: list[str] | tuple[str, ...]) -> F64 | None:
        found = [r for r in roles if r in mk.found]
        return np.mean([mk(r) for r in found], axis=0) if found else None

    def centre(group: str) -> F64 | None:
        return mean_of(groups.get(group, ((), ()))[0])

    legs = [c for c in (centre(g) for g in ("leg_l", "leg_r") if g in present) if c is not None]
    # The thorax's own markers last: an upper-body set (seated, in a wheelchair) has no pelvis.
    pairs = [(centre("pelvis"), np.mean(legs, axis=0) if legs else None),
             (centre("trunk"), centre("pelvis")), (centre("head"), centre("trunk")),
             (mean_of(("IJ", "C7")), mean_of(("PX", "T10")))]
    sign = 0.0
    for high, low in pairs:
        if high is not None and low is not None:
            sign = float(np.median((high - low)[:, axis]))
            break
    name = "xyz"[axis]
    if sign <= 0:
        raise EcsAnimError(f"cannot tell the up axis (the body is tallest along {name}, "
                           "downwards); give --up")
    return name


def import_c3d(path: str | Path, map_spec: str | None = None, unit: str | None = None,
               thresholds: ContactThresholds = ContactThresholds(), up: str | None = None,
               max_gap: int | None = None, fill_from: str | Path | None = None,
               trim: FrameRange | None = None, treadmill: bool = True,
               contacts: str = "detect") -> NormalizedMotion:
    """Read a C3D file and normalize it. Raises :class:`EcsAnimError` subclasses on bad input.

    ``fill_from``: a motion (.nmo or .bvh) whose parts replace the absent ones (see
    :func:`fill_absent_from`); by default they keep the neutral pose. ``trim``: only those
    frames (numbered as in the file); without it a leading rest pose is dropped
    (:func:`~ecs_anim.io.importing.leading_rest_frames`, ``info.rest_frames_dropped``). The file's
    gait events go to ``info.gait_events``; ``contacts="events"`` makes them the foot contacts;
    ``treadmill`` as in
    :func:`~ecs_anim.io.importing.normalize_clip`.
    """
    path = Path(path)
    raw = read_c3d(path)
    try:
        clip, extra = canonical_clip_c3d(raw, map_spec, unit, up, max_gap)
        if trim is not None:
            kept = trim.frames(len(clip.positions), clip.fps, extra["first_file_frame"])
            clip = trim_clip(clip, kept)
            extra = _after_trim(extra, kept)
        else:
            rest = leading_rest_frames(clip.positions, clip.fps)
            if rest is not None:
                kept = slice(rest.count, len(clip.positions))
                rest_line = rest.report(extra["first_file_frame"])
                clip = trim_clip(clip, kept)
                extra = dict(_after_trim(extra, kept), rest_frames_dropped=rest_line)
        # EVENT:TIMES count from the capture's start; the clip's frame 0 is the file's frame
        # first_frame - 1 + first_file_frame (0-based) of it.
        start_s = (raw.first_frame - 1 + extra["first_file_frame"]) / raw.rate
        events = gait_events(raw.events, start_s)
        motion = normalize_clip(clip, path.stem, str(path), thresholds, treadmill, events,
                                contacts)
        if events or raw.events:
            extra["gait_events"] = events
        _check_against_plates(raw, clip, extra["first_file_frame"], motion, extra)
    except InputError:
        raise
    except EcsAnimError as exc:
        raise InputError(path, str(exc)) from None
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise InputError(path, f"cannot compute joint centres from these markers: {exc}") from None
    bad = [k for k, v in motion.poses.arrays().items() if not np.all(np.isfinite(v))]
    if bad:
        raise InputError(path, f"normalizing gave non-finite values in {', '.join(bad)} "
                               "(degenerate marker data?); nothing written")
    motion.info.update(extra)
    if fill_from is not None:
        motion = fill_absent_from(motion, _load_default(Path(fill_from)), Path(fill_from).name,
                                  thresholds)
    return motion


def _check_against_plates(raw: C3dMarkers, clip: CanonicalClip, first_file_frame: int,
                          motion: NormalizedMotion, extra: dict[str, Any]) -> None:
    """The foot contacts the file's force plates measured (``extra["force_plates"]``) and how
    far the motion's contacts lie from their touch-downs and lift-offs
    (``motion.info["contacts"]["plates_check"]``, as ``events_check``)."""
    plate2clip = UNITS[clip.unit] * UP_AXES[clip.up_axis]
    measured, notes = plate_contacts(raw.force_plates, plate2clip, clip.positions, clip.fps,
                                     first_file_frame / raw.rate)
    notes = ([raw.force_plate_note] if raw.force_plate_note else []) + notes
    if notes:
        extra["force_plate_notes"] = notes
    if not measured:
        return
    extra["force_plates"] = measured
    edges = plate_edges(measured)
    if edges and motion.planted is not None:
        motion.info["contacts"]["plates_check"] = event_agreement(
            motion.planted["on_ground"], edges, motion.fps)


def gait_events(stored: list[tuple[str, str, float]], start_s: float) -> list[dict[str, Any]]:
    """A file's ``EVENT`` entries as gait events in the clip's seconds (``time_s``, from its
    first frame at ``start_s`` of the capture), sorted by time: ``side`` ``"l"``/``"r"`` and
    ``kind`` ``"strike"``/``"off"`` where the label and context say so
    (:func:`~ecs_anim.io.contacts.gait_event_kind`), ``None`` for other events."""
    out = []
    for label, context, time_s in stored:
        kind = gait_event_kind(label, context)
        out.append({"label": label, "context": context, "side": kind[0] if kind else None,
                    "kind": kind[1] if kind else None, "time_s": round(time_s - start_s, 6),
                    "file_time_s": round(time_s, 6)})
    return sorted(out, key=lambda e: e["time_s"])


def _after_trim(extra: dict[str, Any], kept: slice) -> dict[str, Any]:
    """``extra``'s frame spans (numbered as the motion's frames) after keeping only ``kept``."""
    def spans(pairs: list[list[int]]) -> list[list[int]]:
        return [[max(a, kept.start) - kept.start, min(b, kept.stop - 1) - kept.start]
                for a, b in pairs if b >= kept.start and a < kept.stop]

    gaps = dict(extra["gaps"], long_gap_frames=spans(extra["gaps"]["long_gap_frames"]))
    return dict(extra, gaps=gaps, root_frames_repaired=spans(extra["root_frames_repaired"]),
                first_file_frame=extra["first_file_frame"] + kept.start)


def _load_default(path: Path) -> NormalizedMotion:
    from ecs_anim.io.importing import import_bvh
    from ecs_anim.motion.clip import load_nmo

    if path.suffix.lower() == ".nmo":
        return load_nmo(path)
    if path.suffix.lower() == ".bvh":
        return import_bvh(path)
    raise EcsAnimError(f"--fill-absent-from {path}: expected a .nmo or .bvh motion")


#: Normalized fields of each body group: (field, side index or None).
GROUP_FIELDS: dict[str, tuple[tuple[str, int | None], ...]] = {
    "trunk": (("spine_points", None), ("thorax", None)),
    "head": (("neck_dir", None), ("head", None), ("head_top_dir", None)),
    **{f"arm_{s}": (("clavicle_dir", i), ("arm_frame", i), ("arm_fraction", i), ("hand_dir", i))
       for i, s in enumerate("lr")},
    **{f"leg_{s}": (("hip_dir", i), ("leg_frame", i), ("leg_fraction", i), ("foot_dir", i))
       for i, s in enumerate("lr")},
}
GROUP_SEGMENTS: dict[str, tuple[str, ...]] = {
    "trunk": ("spine_lower", "spine_middle", "spine_upper"), "head": ("neck", "head"),
    **{f"arm_{s}": (f"clavicle_{s}", f"upper_arm_{s}", f"forearm_{s}", f"hand_{s}") for s in "lr"},
    **{f"leg_{s}": (f"pelvis_{s}", f"thigh_{s}", f"shank_{s}", f"foot_{s}") for s in "lr"},
}


def fill_absent_from(motion: NormalizedMotion, default: NormalizedMotion, default_name: str,
                     thresholds: ContactThresholds = ContactThresholds()) -> NormalizedMotion:
    """Replace the absent body parts of ``motion`` (``info.absent``) by those of a default
    motion, frame by frame at the same time (the default loops), in normalized form: the parts
    are relative to their parent part, so e.g. a walk's arm swing rides on the captured trunk.
    The pelvis is never taken from the default. Foot contacts are detected again when legs were
    replaced. Returns a new motion; ``info.absent_fill`` names the default.
    """
    from ecs_anim.core.normalized import NormalizedPoses, decode
    from ecs_anim.core.skeleton import LENGTH_INDEX
    from ecs_anim.io.contacts import contact_constraints, detect_foot_contacts

    groups = [g for g in motion.info.get("absent", []) if g in GROUP_FIELDS]
    if not groups:
        return motion
    t = np.arange(motion.n_frames) / motion.fps
    index = np.round(t * default.fps).astype(int) % default.n_frames
    arrays = {k: v.copy() for k, v in motion.poses.arrays().items()}
    source = default.poses.arrays()
    for group in groups:
        for name, side in GROUP_FIELDS[group]:
            if side is None:
                arrays[name] = source[name][index].copy()
            else:
                arrays[name][:, side] = source[name][index, side]
        for segment in GROUP_SEGMENTS[group]:
            arrays["stretch"][:, LENGTH_INDEX[segment]] = 1.0
    poses = NormalizedPoses(**arrays)
    constraints, planted = motion.constraints, motion.planted
    if any(g.startswith("leg_") for g in groups):
        positions = decode(poses, motion.source_morphology.lengths, use_stretch=True).positions
        found = detect_foot_contacts(positions, motion.fps, thresholds)
        constraints = [c for c in motion.constraints if c.kind != "foot_contact"] + \
            contact_constraints(found.foot, motion.fps, thresholds)
        planted = {"heel": found.heel, "ball": found.ball, "foot": found.foot,
                   "on_ground": found.on_ground}
    info = dict(motion.info) | {"absent_fill": f"from {default_name}"}
    return NormalizedMotion(poses, motion.fps, motion.source_morphology, constraints, info,
                            planted)


def _match_labels(raw: C3dMarkers, map_spec: str | None, usable: list[bool]
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


def canonical_clip_c3d(raw: C3dMarkers, map_spec: str | None = None, unit: str | None = None,
                       up: str | None = None, max_gap: int | None = None
                       ) -> tuple[CanonicalClip, dict[str, Any]]:
    """Markers -> canonical clip (metres, Z up) plus provenance for ``info``. ``max_gap``
    (frames): None for :data:`DEFAULT_MAX_GAP_S` at the file's rate."""
    if max_gap is None:
        max_gap = frames_of(DEFAULT_MAX_GAP_S, raw.rate)
    # Markers never seen in the trial count as missing.
    seen: BOOL = np.asarray(raw.valid.any(axis=0))
    mmap, labels = _match_labels(raw, map_spec, [bool(v) for v in seen])
    raw = replace(raw, labels=labels)
    mmap.unseen = {r: raw.labels[i] for r, i in mmap.marker.items() if not seen[i]}
    never = list(dict.fromkeys(mmap.unseen.values()))
    mmap.marker = {r: i for r, i in mmap.marker.items() if seen[i]}
    split_same_label(mmap, raw.positions, raw.valid)
    present, absent = check_usable(mmap, raw.labels)
    # Units (before the cluster check below, whose tolerance is a length).
    if unit is not None:
        if unit not in UNITS:
            raise EcsAnimError(f"--unit {unit}: unknown unit; choose one of {', '.join(UNITS)}")
        unit_name, reason = unit, "given with --unit"
    elif raw.units in ("mm", "cm", "m"):
        unit_name, reason = raw.units, f"POINT:UNITS says {raw.units!r}"
    else:
        # The body's size, as BVH import reads it: the markers' spread along the axis the body
        # is tallest on (whichever is up), over frames, as a leg length (a standing adult's
        # markers span about 1.9 legs; a lower-body set about 1.1, which still tells mm from cm
        # and m apart).
        used = sorted(set(mmap.marker.values())) or list(range(raw.positions.shape[1]))
        body = np.where(raw.valid[:, used, None], raw.positions[:, used], np.nan)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            spread = np.nanmedian(np.nanmax(body, axis=1) - np.nanmin(body, axis=1), axis=0)
        tallest = float(np.nanmax(spread)) if np.isfinite(spread).any() else 0.0
        unit_name, reason = detect_unit(tallest / 1.9)
        what = "there is no POINT:UNITS" if not raw.units else f"POINT:UNITS is {raw.units!r}"
        reason = f"{what}; guessed from the body's size: {reason}"
    valid = raw.valid.copy()
    rejected = 0
    if mmap.preset.method == "functional":  # rigid clusters: drop samples that break the shape
        for members in _clusters(mmap):
            out = cluster_outliers(raw.positions[:, members], valid[:, members],
                                   0.015 / UNITS[unit_name])
            rejected += int(out.sum())
            valid[:, members] &= ~out
    filled, unreliable = fill_gaps(raw.positions, valid, max_gap)
    scale = UNITS[unit_name]
    mk = _Markers(filled * scale, unreliable, mmap.marker, raw.anthropometry, raw.lab_model)
    if up is None:
        up = _detect_up(mk, present, mmap)
        up_reason = "detected from the markers"
    else:
        up_reason = "given with --up"
    if up not in UP_AXES:
        raise EcsAnimError(f"--up {up}: expected {', '.join(UP_AXES)}")
    if up != "z":
        mk.points = mk.points @ UP_AXES[up].T
    build, root, kept, repaired = _joint_centres(mk, mmap, present)
    parts_trimmed = _parts_trimmed(mk, mmap, present, raw.labels, root, kept)
    unreliable, valid = unreliable[kept], valid[kept]
    lab = lab_joint_centres(raw.labels, mk.points[kept], valid, build.positions, mmap, present)
    rejected_joints = reject_joint_outliers(build.positions, build.measured,
                                            frames_of(MAX_GLITCH_S, raw.rate))
    # Frames where a marker was in a long gap or held at an end (not trimmed: kept_frames).
    used = sorted(set(mmap.marker.values()))
    bad_frames: BOOL = np.asarray(unreliable[:, used].any(axis=1)) if used else \
        np.zeros(unreliable.shape[0], dtype=bool)
    gap_markers = {raw.labels[i]: int(unreliable[:, i].sum()) for i in used if unreliable[:, i].any()}
    n_filled = int((~valid[:, used]).sum()) if used else 0
    if not np.all(np.isfinite(build.positions)):
        raise EcsAnimError("joint centres hold non-finite values (degenerate marker data)")
    jmap = JointMap(source={}, thorax=-1, how=mmap.how,
                    names={j: build.how.get(j) for j in JOINTS})
    clip = CanonicalClip(
        positions=build.positions, pelvis2world=build.pelvis2world,  # type: ignore[arg-type]
        thorax2world=build.thorax2world, head2world=build.head2world,  # type: ignore[arg-type]
        measured=build.measured, fps=raw.rate, unit=unit_name, unit_reason=reason,
        joint_map=jmap, up_axis=up,
    )
    extra: dict[str, Any] = {
        "format_in": "c3d",
        "marker_set": mmap.preset.name,
        "subject": mmap.subject,
        "ignored_markers": mmap.ignored,
        "markers_never_seen": never,
        "up_reason": up_reason,
        "absent": absent,
        # Parts with some of their markers, not computed: one message each (part, found, lacking).
        "parts_not_computed": dict(mmap.not_computed),
        "absent_fill": "neutral pose" if absent else None,
        # Ours against the centres the lab's model stored in the file (LHJC, VRKN, "r ankle").
        "lab_joint_centres": lab,
        # Where the pelvis markers could not place the pelvis: trimmed (numbered as in the file,
        # from 0), repaired (numbered as the motion's frames, like the gaps below).
        "root_frames_trimmed": [[a, b] for a, b in ((0, root.start - 1), (root.stop, raw.positions.shape[0] - 1))
                                if a <= b],
        # Beyond those, frames at the ends where a part's own markers were not seen: one line each.
        "parts_frames_trimmed": parts_trimmed,
        # The motion's frame 0 is this frame of the file: times given against the file (a
        # --constraints file, gait events) are shifted by it.
        "first_file_frame": kept.start,
        "root_frames_repaired": repaired,
        "gaps": {
            "max_gap_frames": max_gap,
            "samples_filled": n_filled,
            "samples_rejected_as_outliers": rejected,
            "long_gap_frames": [[a, b] for a, b in true_runs(bad_frames)],
            "long_gap_samples_per_marker": gap_markers,
            "joint_centres_rejected": rejected_joints,
        },
    }
    return clip, extra


def _parts_trimmed(mk: _Markers, mmap: MarkerMap, present: list[str], labels: list[str],
                   root: slice, kept: slice) -> list[str]:
    """One line per end of the pelvis' span trimmed because a part's markers did not place it
    (:func:`kept_frames`), naming those parts and their markers unseen or unreliable there."""
    placed = parts_placed(mk, mmap, present)
    out = []
    for first, stop in ((root.start, kept.start), (kept.stop, root.stop)):
        if first >= stop:
            continue
        parts = []
        for group, where in placed.items():
            unplaced = ~where[first:stop]
            markers = [labels[mk.found[r]] for r in part_roles(mmap.preset, group)
                       if r in mk.found and (mk.unreliable[first:stop, mk.found[r]] & unplaced).any()]
            if unplaced.any():
                parts.append(f"{GROUP_WORDS[group]} ({listed(markers, 4)})")
        frames = f"frame {first}" if stop - first == 1 else f"frames {first}-{stop - 1}"
        out.append(f"{frames} of the file trimmed: the markers of the {listed(parts, 3)} are "
                   "unseen or in a long gap there")
    return out


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


#: A part whose markers are missing at the trial's start or end gets those frames trimmed,
#: unless that keeps less than this share of the frames the pelvis markers place (then the
#: frames are kept and reported with the long gaps).
MIN_KEPT_SHARE = 0.5


def parts_placed(mk: _Markers, mmap: MarkerMap, present: list[str]) -> dict[str, BOOL]:
    """Per present body part but the pelvis (``root_trusted`` places it), the frames (F,) bool
    where its own markers place it: none of its markers unreliable (:func:`fill_gaps`: in a
    long gap, or held at the trial's start or end where it is not seen); in a cluster set, each
    of its clusters with three reliable markers (what a rigid fit needs). Elsewhere its joints
    are a guess."""
    out: dict[str, BOOL] = {}
    for group in (g for g in present if g != "pelvis"):
        roles = [r for r in part_roles(mmap.preset, group) if r in mk.found]
        reliable = ~mk.unreliable[:, [mk.found[r] for r in roles]]
        if mmap.preset.method == "functional":
            clusters: dict[str, list[int]] = {}
            for k, role in enumerate(roles):
                clusters.setdefault(_cluster_key(role), []).append(k)
            out[group] = np.all([reliable[:, ks].sum(axis=1) >= 3 for ks in clusters.values()],
                                axis=0)
        else:
            out[group] = np.asarray(reliable.all(axis=1))
    return out


def kept_frames(root_trusted: BOOL | None, placed: dict[str, BOOL], n: int) -> tuple[slice, slice]:
    """(the pelvis' span, the frames kept), file frames: the pelvis' span runs from the first to
    the last frame whose pelvis frame the markers determine (``root_trusted`` (n,), None: all);
    the frames kept, from the first to the last of those where every part is ``placed`` too
    (:func:`parts_placed`), unless that would keep less than :data:`MIN_KEPT_SHARE` of the
    pelvis' span or nothing (then the pelvis' span). Raises :class:`EcsAnimError` when the
    pelvis is placed nowhere."""
    trusted = np.ones(n, dtype=bool) if root_trusted is None else root_trusted
    good = np.flatnonzero(trusted)
    if len(good) == 0:
        raise EcsAnimError(f"the pelvis markers place the pelvis in none of the {n} frames "
                           "(a cluster needs three of its markers seen, landmarks all of theirs); "
                           "nothing to import")
    root = slice(int(good[0]), int(good[-1]) + 1)
    everything = np.flatnonzero(trusted & np.all(list(placed.values()), axis=0)) if placed else good
    if len(everything) and everything[-1] + 1 - everything[0] >= MIN_KEPT_SHARE * (root.stop - root.start):
        return root, slice(int(everything[0]), int(everything[-1]) + 1)
    return root, root


def trust_root(build: _Build, kept: slice) -> list[list[int]]:
    """Keep only the frames ``kept`` (:func:`kept_frames`) and repair those inside whose pelvis
    frame the markers do not determine, in place.

    Where the pelvis markers are missing (a cluster with fewer than three seen, a landmark in a
    long gap), the computed pelvis frame is noise: it flipped the body upside down from one
    frame to the next, and every part filled in or taken from a default motion followed it.
    Such runs at the start and end of the trial are trimmed (the capture had not started yet);
    inside it, the pelvis frame is interpolated along the shorter arc, and the pelvis and hip
    centres (placed from it) linearly, between the trusted frames on either side (``kept``
    starts and ends on such frames). Joints that their own markers place are kept.

    Returns the repaired runs as ``[first, last]`` pairs in the kept frames' numbering (the
    motion's).
    """
    assert build.pelvis2world is not None, "every pelvis builder sets the pelvis frame"
    n = build.positions.shape[0]
    trusted = np.ones(n, dtype=bool) if build.root_trusted is None else build.root_trusted
    repaired = [[a, b] for a, b in true_runs(~trusted[kept])]
    frames = [f for f in ("pelvis2world", "thorax2world", "head2world") if getattr(build, f) is not None]
    build.positions = build.positions[kept]
    for name in frames:
        setattr(build, name, getattr(build, name)[kept])
    for first, last in repaired:
        before, after = first - 1, last + 1
        t = (np.arange(first, last + 1) - before) / (after - before)
        root = [J["pelvis"], J["hip_l"], J["hip_r"]]
        build.positions[before + 1:after, root] = (1.0 - t[:, None, None]) * build.positions[before, root] \
            + t[:, None, None] * build.positions[after, root]
        quats = quat_from_matrix(build.pelvis2world[[before, after]])
        build.pelvis2world[before + 1:after] = matrix_from_quat(slerp(quats[0], quats[1], t))
    build.root_trusted = None
    return repaired


def reject_joint_outliers(positions: F64, measured: BOOL, longest: int, tolerance: float = 0.15
                          ) -> dict[str, int]:
    """Replace limb joint centres that break their bone lengths (marker swaps, ghost markers
    in fast motion) by interpolation from the neighbouring frames, in place.

    positions (F, N_JOINTS, 3). A bone is off in a frame when its length differs from its
    median over the trial by more than ``tolerance`` of it; only runs of at most ``longest``
    frames (:data:`MAX_GLITCH_S` at the file's rate) are replaced (longer runs are motion, or
    the model).
    Along hip-knee-ankle-toe and shoulder-elbow-wrist-hand, the middle joint (knee, elbow) is
    the culprit where the shank (forearm) is off and so is the thigh (upper arm), or the foot
    (hand) beyond it is not; the end joint (ankle, wrist) where the shank (forearm) is still
    off after that; then the toe (hand end) where the foot (hand) is off. Returns joint -> replaced frame count (only joints with some).
    """
    frames = np.arange(positions.shape[0])
    out: dict[str, int] = {}

    def off(p: int, q: int) -> BOOL:
        length = np.linalg.norm(positions[:, q] - positions[:, p], axis=-1)
        median = np.median(length)
        bad: BOOL = np.abs(length - median) > tolerance * median
        return bad

    for s in "lr":
        for top, middle, end, tip in (("hip", "knee", "ankle", "toe"),
                                      ("shoulder", "elbow", "wrist", "hand")):
            a, b, c, d = (J[f"{n}_{s}"] for n in (top, middle, end, tip))
            if not measured[[a, b, c]].all():
                continue
            lower = off(b, c)
            tip_fine = ~off(c, d) if measured[d] else np.zeros_like(lower)
            _interpolate_frames(positions, b, lower & (off(a, b) | tip_fine), frames, longest,
                                out)
            _interpolate_frames(positions, c, off(b, c), frames, longest, out)  # after the fix
            if measured[d]:
                _interpolate_frames(positions, d, off(c, d), frames, longest, out)
    return out


def _interpolate_frames(positions: F64, joint: int, bad: BOOL, frames: NDArray[np.int_],
                        longest: int, counts: dict[str, int]) -> None:
    bad = bad.copy()
    for a, b in true_runs(bad):  # a long run is the motion (or the model), not a glitch
        if b - a + 1 > longest:
            bad[a:b + 1] = False
    if bad.any() and not bad.all():
        for axis in range(3):
            positions[bad, joint, axis] = np.interp(frames[bad], frames[~bad],
                                                    positions[~bad, joint, axis])
        counts[JOINTS[joint]] = counts.get(JOINTS[joint], 0) + int(bad.sum())


def _cluster_key(role: str) -> str:
    """The rigid cluster a functional set's role belongs to (``THIGH_2_l`` -> ``THIGH_l``)."""
    parts = role.split("_")
    return parts[0] + ("_" + parts[2] if len(parts) > 2 else "")


def _clusters(mmap: MarkerMap) -> list[list[int]]:
    """Marker indices of each rigid cluster of a functional marker set (by role prefix)."""
    groups: dict[str, list[int]] = {}
    for role, i in mmap.marker.items():
        groups.setdefault(_cluster_key(role), []).append(i)
    return [g for g in groups.values() if len(g) >= 3]


def _joint_centres(mk: _Markers, mmap: MarkerMap, present: list[str]
                   ) -> tuple[_Build, slice, slice, list[list[int]]]:
    """Joint centres and frames of every frame kept, with :func:`kept_frames`' slices (the
    pelvis' span, the frames kept) and :func:`trust_root`'s repaired runs; absent parts are
    filled on the trusted pelvis frame."""
    n = mk.points.shape[0]
    build = _Build(np.zeros((n, N_JOINTS, 3)), np.zeros(N_JOINTS, dtype=bool))
    if mmap.preset.method == "functional":
        _functional_lower_body(mk, present, build)
    else:
        _landmark_body(mk, present, build)
    root, kept = kept_frames(build.root_trusted, parts_placed(mk, mmap, present), n)
    repaired = trust_root(build, kept)
    _fill_absent(build, present)
    return build, root, kept, repaired


def _set(build: _Build, joint: str, value: F64, how: str) -> None:
    build.positions[:, J[joint]] = value
    build.measured[J[joint]] = True
    build.how[joint] = how


def _heading_frame(pelvis2world: F64) -> F64:
    return rot_axis(2, yaw_of(pelvis2world))


def _leg_length(build: _Build, present: list[str]) -> float:
    p = build.positions
    legs = [s for s in "lr" if f"leg_{s}" in present]
    if legs:
        return float(np.mean([np.median(np.linalg.norm(p[:, J[f"knee_{s}"]] - p[:, J[f"hip_{s}"]], axis=-1)
                                        + np.linalg.norm(p[:, J[f"ankle_{s}"]] - p[:, J[f"knee_{s}"]], axis=-1))
                              for s in legs]))
    if "trunk" in present:
        spine = np.median(np.linalg.norm(p[:, J["neck"]] - p[:, J["pelvis"]], axis=-1))
        return float(spine / sum(ADULT_PROPORTIONS[k] for k in ("spine_lower", "spine_middle",
                                                                  "spine_upper")) * _LEG_P)
    width = np.median(np.linalg.norm(p[:, J["hip_l"]] - p[:, J["hip_r"]], axis=-1))
    return float(width / (2 * ADULT_PROPORTIONS["pelvis"] * REST_HIP_DIR_LEFT[1]) * _LEG_P)


def _landmark_pelvis(mk: _Markers, build: _Build) -> None:
    # Pelvis (ISB-like frame: y along ASIS_r -> ASIS_l, x forward in the ASIS/PSIS plane).
    asis_l, asis_r = mk("ASIS_l"), mk("ASIS_r")
    back = _mid(mk("PSIS_l"), mk("PSIS_r")) if mk.has("PSIS_l", "PSIS_r") else mk("SACRUM")
    back_name = "LPSI/RPSI" if mk.has("PSIS_l", "PSIS_r") else "SACR"
    front = _mid(asis_l, asis_r)
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
        _set(build, f"hip_{s}", front + pelvis2world @ local, how)
    _set(build, "pelvis", _mid(build.positions[:, J["hip_l"]], build.positions[:, J["hip_r"]]),
         "midpoint of the hip centres")
    build.pelvis2world = pelvis2world


#: Davis et al. 1991 (Hum Mov Sci 10:575): the hip lies C = 0.115 L - 15.3 mm (L the leg
#: length, the mean of both legs as Plug-in Gait takes it) from the ASIS along a line at THETA to
#: the frontal plane and BETA to the transverse one (0.5 and 0.314 rad, the values Plug-in Gait
#: and pyCGM use), set back by the ASIS-trochanter distance plus a marker radius. Without a
#: measured distance the model takes 0.1288 L - 48.56 mm, which Plug-in Gait writes back to the
#: file.
DAVIS_C_PER_LEG, DAVIS_C_M = 0.115, -0.0153
DAVIS_THETA_RAD, DAVIS_BETA_RAD = 0.5, 0.314
DAVIS_TROCHANTER_PER_LEG, DAVIS_TROCHANTER_M = 0.1288, -0.04856
#: Hara et al. 2016 (Sci Rep 6:37707), in the pelvis frame from the mid-ASIS: (forward, lateral,
#: up) = HARA_PER_LEG * L + HARA_M (L the leg length). pyCGM2 moves it back by the marker radius
#: and a 2 mm base plate (its markers sit on the skin, the regression's on the bone).
HARA_PER_LEG = np.array([-0.063, 0.086, -0.078])
HARA_M = np.array([0.011, 0.008, -0.009])
HARA_BASE_PLATE_M = 0.002


def lab_model_hip(anthropometry: dict[str, float], lab_model: str, side: str,
                  marker_radius_m: float, asis_width_m: float) -> tuple[F64, str] | None:
    """The hip of ``side`` in the pelvis frame (x forward, y the lateral distance, z up; from
    the mid-ASIS; (3,) metres) as the lab's model placed it from the subject's leg length the
    file stores, with how it was placed; None where the file stores no leg length.

    A file that stores a leg length was processed by a lab's model, whose centres it often holds
    too: pyCGM2's CGM 2.1 and later (``lab_model``) place the hips by Hara 2016; Plug-in Gait
    (and BTS's Davis protocol) by Davis 1991 with the file's ASIS-trochanter distance, measured or
    the model's own regression on the leg, and the inter-ASIS distance (else the markers',
    ``asis_width_m``). Measured on the files here that store centres: Hara puts ours 4-5 mm from
    a CGM 2.4 file's (Harrington from the markers: 20-25 mm), Davis with a measured trochanter
    distance 6-13 mm from BTS's (Harrington: 21-26 mm). Davis on its regressed distance is
    unmeasured against a lab's centres (on the CGM 2.4 file, its model's name removed: 19 mm);
    a CGM 2.x file that does not name its model gets Davis."""
    leg = anthropometry.get(f"leg_length_{side}")
    if leg is None:
        return None
    if lab_model.startswith("CGM 2."):
        local = HARA_PER_LEG * leg + HARA_M
        local[0] -= marker_radius_m + HARA_BASE_PLATE_M
        return local, (f"Hara 2016 with the file's leg length {leg * 1000:.0f} mm ({lab_model}, "
                       "as the file says)")
    trochanter = anthropometry.get(f"asis_trochanter_{side}",
                                   DAVIS_TROCHANTER_PER_LEG * leg + DAVIS_TROCHANTER_M)
    asis = anthropometry.get("asis_distance", asis_width_m)
    both_legs = [anthropometry[k] for k in ("leg_length_l", "leg_length_r") if k in anthropometry]
    c = DAVIS_C_PER_LEG * float(np.mean(both_legs)) + DAVIS_C_M
    theta, beta = DAVIS_THETA_RAD, DAVIS_BETA_RAD
    back = trochanter + marker_radius_m
    local = np.array([c * math.cos(theta) * math.sin(beta) - back * math.cos(beta),
                      0.5 * asis - c * math.sin(theta),
                      -c * math.cos(theta) * math.cos(beta) - back * math.sin(beta)])
    return local, (f"Davis 1991 with the file's leg length {leg * 1000:.0f} mm, ASIS-trochanter "
                   f"distance {trochanter * 1000:.0f} mm and ASIS distance {asis * 1000:.0f} mm")


def _pelvis_under_trunk(mk: _Markers, present: list[str], build: _Build) -> None:
    """Upper-body trials: the pelvis (not marked) hangs a spine length below the neck base along
    the thorax axis, upright, facing the thorax' heading. The body's size comes from the
    acromion distance (two clavicles of adult proportions) when both arms are marked."""
    neck = _mid(mk("C7"), mk("IJ"))
    if mk.has("T10", "PX"):
        axis = normalize(neck - _mid(mk("T10"), mk("PX")))
    else:
        axis = np.broadcast_to(np.array([0.0, 0.0, 1.0]), neck.shape)
    thorax2world = frame_from_axes(axis, mk("IJ") - mk("C7"), 2, 0)
    roles = ["C7", "IJ"] + (["T10", "PX"] if mk.has("T10", "PX") else [])
    build.root_trusted = np.asarray(~mk.unreliable[:, [mk.found[r] for r in roles]].any(axis=1))
    if "arm_l" in present and "arm_r" in present:
        width = float(np.median(np.linalg.norm(mk("ACROMION_l") - mk("ACROMION_r"), axis=-1)))
        leg = width / (2 * ADULT_PROPORTIONS["clavicle"]) * _LEG_P
    else:
        leg = 0.8
    spine = sum(_prop(k, leg) for k in ("spine_lower", "spine_middle", "spine_upper"))
    build.positions[:, J["pelvis"]] = neck - spine * axis
    build.pelvis2world = _heading_frame(thorax2world)
    build.how["pelvis"] = "not marked: a spine length below the neck base"


def _landmark_body(mk: _Markers, present: list[str], build: _Build) -> None:
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
            _set(build, f"toe_{s}", mk(f"TOE_{s}"), "TOE marker (2nd metatarsal head)")
        else:
            _set(build, f"toe_{s}", _mid(mk(f"MT1_{s}"), mk(f"MT5_{s}")), "midpoint of MT1 and MT5")
    # Trunk.
    if "trunk" in present:
        c7, ij = mk("C7"), mk("IJ")
        neck = _mid(c7, ij)
        _set(build, "neck", neck, "midpoint of C7 and the jugular notch")
        pelvis = build.positions[:, J["pelvis"]]
        if mk.has("T10", "PX"):
            mid = _mid(mk("T10"), mk("PX"))
            _set(build, "spine_2", mid, "midpoint of T10/T8 and the xiphoid")
            _set(build, "spine_1", _mid(pelvis, mid), "")
            build.measured[J["spine_1"]] = False
            front, rear = _mid(ij, mk("PX")), _mid(c7, mk("T10"))
        else:
            mid = pelvis + (neck - pelvis) * (2 / 3)
            build.positions[:, J["spine_1"]] = pelvis + (neck - pelvis) / 3
            build.positions[:, J["spine_2"]] = mid
            front, rear = ij, c7
        build.thorax2world = frame_from_axes(neck - mid, front - rear, 2, 0)
    leg = _leg_length(build, present)  # (with no legs, from the trunk: after it)
    # Arms.
    thorax = build.thorax2world
    acromion_width = None
    if "arm_l" in present and "arm_r" in present:
        acromion_width = float(np.median(np.linalg.norm(mk("ACROMION_l") - mk("ACROMION_r"), axis=-1)))
    for s, medial_sign in (("l", -1.0), ("r", 1.0)):
        if f"arm_{s}" not in present:
            continue
        down = -(thorax[..., :, 2] if thorax is not None else np.array([0.0, 0.0, 1.0]))
        aw = acromion_width if acromion_width is not None else 2 * _prop("clavicle", leg) + 0.08
        shoulder = mk(f"ACROMION_{s}") + SHOULDER_DROP * aw * down
        _set(build, f"shoulder_{s}", shoulder,
             f"{SHOULDER_DROP:.0%} of the acromion distance ({aw * 1000:.0f} mm) below the acromion")
        if mk.has(f"WRIST_RAD_{s}", f"WRIST_ULN_{s}"):
            wrist = _mid(mk(f"WRIST_RAD_{s}"), mk(f"WRIST_ULN_{s}"))
            _set(build, f"wrist_{s}", wrist, "midpoint of the wrist markers")
        else:
            wrist = mk(f"WRIST_{s}")
            _set(build, f"wrist_{s}", wrist, "the wrist marker")
        lateral = mk(f"ELBOW_LAT_{s}")
        if mk.has(f"ELBOW_MED_{s}"):
            _set(build, f"elbow_{s}", _mid(lateral, mk(f"ELBOW_MED_{s}")),
                 "midpoint of the humeral epicondyles")
        else:
            second = mk(f"UPPER_ARM_{s}") - lateral if mk.has(f"UPPER_ARM_{s}") else \
                np.broadcast_to(thorax[..., :, 0] if thorax is not None else [1.0, 0.0, 0.0], lateral.shape)
            medial = medial_sign * flexion_axis(shoulder, lateral, wrist, second)
            d = 0.5 * JOINT_WIDTH_PER_LEG["elbow"] * leg + MARKER_RADIUS_M
            _set(build, f"elbow_{s}", lateral + d * medial,
                 f"ELB moved {d * 1000:.0f} mm medially along the flexion axis")
        if mk.has(f"HAND_{s}"):
            _set(build, f"hand_{s}", mk(f"HAND_{s}"), "FIN marker")
        elif mk.has(f"MC2_{s}", f"MC5_{s}"):
            _set(build, f"hand_{s}", _mid(mk(f"MC2_{s}"), mk(f"MC5_{s}")), "midpoint of MC2 and MC5")
        else:
            elbow = build.positions[:, J[f"elbow_{s}"]]
            build.positions[:, J[f"hand_{s}"]] = wrist + normalize(wrist - elbow) * _prop("hand", leg)
    # Head.
    if "head" in present:
        if mk.has("HEAD_FRONT_l", "HEAD_FRONT_r", "HEAD_BACK_l", "HEAD_BACK_r"):
            fl, fr, bl, br = (mk(f"HEAD_{p}_{s}") for p, s in
                              (("FRONT", "l"), ("FRONT", "r"), ("BACK", "l"), ("BACK", "r")))
            centre = 0.25 * (fl + fr + bl + br)
            forward, left = _mid(fl, fr) - _mid(bl, br), _mid(fl, bl) - _mid(fr, br)
        else:  # a marker on each side of the head, level with the forehead's
            centre = _mid(mk("HEAD_SIDE_l"), mk("HEAD_SIDE_r"))
            forward, left = mk("FOREHEAD") - centre, mk("HEAD_SIDE_l") - mk("HEAD_SIDE_r")
        head2world = frame_from_axes(forward, left, 0, 1)
        half = 0.5 * _prop("head", leg)
        _set(build, "head", centre - half * head2world[..., :, 2], "half a head length below the head markers' centre")
        _set(build, "head_top", centre + half * head2world[..., :, 2], "half a head length above it")
        build.head2world = head2world


def _knee_and_ankle(mk: _Markers, build: _Build, s: str, leg_guess: float) -> None:
    """Knee and ankle centres of leg ``s``: midpoints of the epicondyles / malleoli where both
    are marked; otherwise the chord rule, in the plane of the wand (THI / TIB) where the wand
    stands out laterally along the flexion axis (within :data:`WAND_MAX_ANGLE_DEG`, as Plug-in
    Gait and Davis 1991 place it), else in the plane of the flexion axis itself.

    The flexion axis is the epicondyle line where the medial epicondyle is marked; otherwise
    the normal of the hip-knee-ankle plane, averaged in the thigh frame (hip-knee, THI) over
    the frames that flex it (:func:`flexion_axis`) and found by iterating from the hip-to-hip
    line: a wand in front of the thigh (a technical marker, as in Motion Analysis' Helen Hayes
    set) would put the centre behind the knee. The axis' sign: towards the other hip."""
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
            knee, knee_how = _mid(knee_lat, mk(f"KNEE_MED_{s}")), "midpoint of the femoral epicondyles"
        else:
            knee, plane = wand_or_axis(hip, knee_lat, f"THIGH_{s}", medial, d_knee)
            knee_how = f"chord rule from hip and KNE in the plane of {plane} (offset {d_knee * 1000:.0f} mm)"
        if mk.has(f"ANKLE_MED_{s}"):
            ankle, ankle_how = _mid(ankle_lat, mk(f"ANKLE_MED_{s}")), "midpoint of the malleoli"
        else:
            ankle, plane = wand_or_axis(knee, ankle_lat, f"SHANK_{s}", medial, d_ankle)
            ankle_how = f"chord rule from knee and ANK in the plane of {plane} (offset {d_ankle * 1000:.0f} mm)"
        if not epicondyles and step < iterations - 1:  # the axis for the next pass
            axis = flexion_axis(hip, knee, ankle, mk(f"THIGH_{s}") - knee, use)
            medial = axis * np.sign(np.median(np.sum(axis * towards_other_hip, axis=-1)[use]))
    _set(build, f"knee_{s}", knee, knee_how)
    _set(build, f"ankle_{s}", ankle, ankle_how)


def _leg_guess_from_markers(mk: _Markers, present: list[str], build: _Build) -> float:
    """Leg length (m) before knees and ankles are known: hip centre to lateral malleolus."""
    values = [np.median(np.linalg.norm(mk(f"ANKLE_LAT_{s}") - build.positions[:, J[f"hip_{s}"]], axis=-1))
              for s in "lr" if f"leg_{s}" in present]
    return float(np.mean(values)) if values else 0.8


def _functional_lower_body(mk: _Markers, present: list[str], build: _Build) -> None:
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
            _set(build, f"hip_{s}", hip, "SCoRE (Ehrig 2006), pelvis and thigh clusters; "
                 f"a flexion-only hip placed {HALF_HIP_DISTANCE_PER_LEG * leg * 1000:.0f} mm "
                 "from the pelvis cluster's mid-plane"
                 + (" on the axis through the greater trochanter" if trochanter is not None else ""))
            _, knee_in_shank, knee = score_centre(thigh[:2], shank[:2], thigh[2] & shank[2],
                                                  hip_in_thigh)
            _set(build, f"knee_{s}", knee, "SCoRE thigh/shank, point of the axis nearest the hip")
            _, _, ankle = score_centre(shank[:2], foot[:2], shank[2] & foot[2], knee_in_shank)
            _set(build, f"ankle_{s}", ankle, "SCoRE shank/foot, point of the axis nearest the knee")
        leg = _leg_length(build, present)
    # Pelvis: between the hips; tilt and roll from the pelvis cluster.
    if "leg_l" in present and "leg_r" in present:
        hip_l, hip_r = build.positions[:, J["hip_l"]], build.positions[:, J["hip_r"]]
        _set(build, "pelvis", _mid(hip_l, hip_r), "midpoint of the hip centres")
        up_local = normalize(np.einsum("fji,j->i", pelvis_rot, np.array([0.0, 0.0, 1.0])))
        build.pelvis2world = frame_from_axes(hip_l - hip_r, pelvis_rot @ up_local, 1, 2)
    else:
        raise EcsAnimError("a cluster marker set needs both leg clusters to place the pelvis "
                           f"(found {', '.join(present)})")
    leg = _leg_length(build, present)
    forward = build.pelvis2world[..., :, 0]
    forward_h = normalize(forward * np.array([1.0, 1.0, 0.0]))
    foot_len = _prop("foot", leg)
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
        _set(build, f"toe_{s}", ankle + foot_rot @ toe_local,
             f"a foot length ({foot_len * 1000:.0f} mm) forward of the ankle, {level}")
        build.measured[J[f"toe_{s}"]] = False


def _fill_absent(build: _Build, present: list[str]) -> None:
    """Neutral pose for absent body parts (upright trunk and head, arms hanging, legs straight),
    adult proportions of the measured leg length. Also spine_1/spine_2 and hand ends that the
    markers do not give."""
    p = build.positions
    assert build.pelvis2world is not None
    leg = _leg_length(build, present)
    heading = _heading_frame(build.pelvis2world)
    up = np.array([0.0, 0.0, 1.0])
    pelvis = p[:, J["pelvis"]]
    for s, sign in (("l", 1.0), ("r", -1.0)):
        if f"leg_{s}" in present:
            continue
        if not build.measured[J[f"hip_{s}"]]:
            x, y, z = REST_HIP_DIR_LEFT
            p[:, J[f"hip_{s}"]] = pelvis + build.pelvis2world @ (np.array([x, sign * y, z]) * _prop("pelvis", leg))
        p[:, J[f"knee_{s}"]] = p[:, J[f"hip_{s}"]] - up * _prop("thigh", leg)
        p[:, J[f"ankle_{s}"]] = p[:, J[f"knee_{s}"]] - up * _prop("shank", leg)
        p[:, J[f"toe_{s}"]] = p[:, J[f"ankle_{s}"]] + heading[..., :, 0] * _prop("foot", leg) * 0.95 \
            - up * _prop("ankle_height", leg)
    if "trunk" not in present:
        p[:, J["spine_1"]] = pelvis + up * _prop("spine_lower", leg)
        p[:, J["spine_2"]] = p[:, J["spine_1"]] + up * _prop("spine_middle", leg)
        p[:, J["neck"]] = p[:, J["spine_2"]] + up * _prop("spine_upper", leg)
        build.thorax2world = heading
    if "head" not in present:
        thorax_up = build.thorax2world[..., :, 2]  # type: ignore[index]
        p[:, J["head"]] = p[:, J["neck"]] + thorax_up * _prop("neck", leg)
        p[:, J["head_top"]] = p[:, J["head"]] + thorax_up * _prop("head", leg)
        build.head2world = build.thorax2world
    thorax = build.thorax2world
    for s, sign in (("l", 1.0), ("r", -1.0)):
        if f"arm_{s}" in present:
            continue
        p[:, J[f"shoulder_{s}"]] = p[:, J["neck"]] + sign * thorax[..., :, 1] * _prop("clavicle", leg)  # type: ignore[index]
        p[:, J[f"elbow_{s}"]] = p[:, J[f"shoulder_{s}"]] - up * _prop("upper_arm", leg)
        p[:, J[f"wrist_{s}"]] = p[:, J[f"elbow_{s}"]] - up * _prop("forearm", leg)
        p[:, J[f"hand_{s}"]] = p[:, J[f"wrist_{s}"]] - up * _prop("hand", leg)


__all__ = [
    "DEFAULT_MAX_GAP_S",
    "GROUPS",
    "C3dMarkers",
    "canonical_clip_c3d",
    "chord_centre",
    "cluster_poses",
    "fill_gaps",
    "import_c3d",
    "lab_model_hip",
    "lab_model_named",
    "read_c3d",
    "score_centre",
]
