"""From labelled C3D markers straight to a :class:`~ecs_anim.motion.clip.NormalizedMotion`: the
import pipeline.

read (:mod:`.reading`) -> match labels to a marker set (:mod:`.label_roles`,
:mod:`ecs_anim.io.c3d.marker_sets`) -> fill short gaps (:mod:`.repair`) -> metres, Z up (the
unit and up axis detected where not given) -> joint centres (:mod:`.joint_centres`: landmark sets
in :mod:`.landmarks`, cluster sets in :mod:`.clusters`; the frames kept in :mod:`.trimming`) ->
the same canonical clip, encoding, source morphology and contact detection as BVH import
(:func:`ecs_anim.io.importing.normalize_clip`), with the file's gait events and force plates
(:mod:`.gait_events`), the lab's stored centres compared (:mod:`.lab_centres`) and absent parts
optionally taken from a default motion (:mod:`.absent_fill`).
No joint angle is ever computed: the representation is Cartesian.
"""

from __future__ import annotations

import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import EcsAnimError, InputError
from ecs_anim.core.skeleton import JOINTS
from ecs_anim.io.c3d.absent_fill import fill_absent_from, load_default_motion
from ecs_anim.io.c3d.centre_build import MarkersByRole
from ecs_anim.io.c3d.clusters import cluster_markers
from ecs_anim.io.c3d.gait_events import check_against_plates, gait_events
from ecs_anim.io.c3d.joint_centres import joint_centres
from ecs_anim.io.c3d.lab_centres import lab_joint_centres
from ecs_anim.io.c3d.label_roles import match_labels, split_same_label
from ecs_anim.io.c3d.marker_sets import MarkerMap, check_usable
from ecs_anim.io.c3d.reading import C3dMarkers, read_c3d
from ecs_anim.io.c3d.repair import (
    DEFAULT_MAX_GAP_S,
    MAX_GLITCH_S,
    cluster_outliers,
    fill_gaps,
    reject_joint_outliers,
)
from ecs_anim.io.c3d.trimming import trimmed_part_lines
from ecs_anim.io.contacts import ContactThresholds, frames_of, true_runs
from ecs_anim.io.importing import (
    UNITS,
    UP_AXES,
    CanonicalClip,
    FrameRange,
    detect_unit,
    leading_rest_frames,
    normalize_clip,
    trim_clip,
)
from ecs_anim.io.joint_map import JointMap
from ecs_anim.motion.clip import NormalizedMotion

F64 = NDArray[np.float64]
BOOL = NDArray[np.bool_]


# --- reading -----------------------------------------------------------------------------------


# --- gaps --------------------------------------------------------------------------------------


# --- small geometric kernels (batched over frames) --------------------------------------------


# --- the importer ------------------------------------------------------------------------------


#: The floor's level varies at most this share of the top's over a trial: a body's lowest
#: markers stand on one plane frame after frame, its highest (the head) bob, bend and squat (on
#: the dev files 0.004-0.69; a body not standing, seated or an arm alone, may not show it).
FLOOR_STEADINESS = 0.75


def _floor_sign(body: F64, axis: int) -> float:
    """+1 when the floor lies at the low end of ``axis`` (up is +axis), -1 at the high end, 0
    when the markers do not tell: the level of the markers' lowest point on each frame (the
    soles on the floor) keeps to one plane while that of their highest moves, its spread over
    frames (10th to 90th percentile) at most :data:`FLOOR_STEADINESS` of the other end's.

    ``body`` (F, M, 3): the body's markers, NaN where not measured."""
    h = body[..., axis]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN frames
        ends = (np.nanmin(h, axis=1), np.nanmax(h, axis=1))
        low, high = (float(np.subtract(*np.nanpercentile(e, [90, 10]))) for e in ends)
    if not (np.isfinite(low) and np.isfinite(high)):
        return 0.0
    if low <= FLOOR_STEADINESS * high:
        return 1.0
    if high <= FLOOR_STEADINESS * low:
        return -1.0
    return 0.0


def _detect_up(mk: MarkersByRole, present: list[str], mmap: MarkerMap) -> str:
    """The file's up axis (``"z"``, ``"-y"``, ...): the axis along which the body is tallest in a
    typical frame (the median over frames of the markers' spread), pointing the way the body's
    parts stand on one another, from each part's markers whether or not the part can be
    computed (the legs' markers below the pelvis's, the pelvis's below the trunk's, the trunk's
    below the head's, or the sternum's and spine's lower markers, PX and T10, below their upper
    ones, IJ and C7), else away from the floor the markers' lowest points keep to
    (:func:`_floor_sign`).
    Raises :class:`EcsAnimError` naming what is missing when neither tells."""
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
        """The mean of the group's markers found (a part lacking one to be computed still
        shows where it is)."""
        required, alternatives = groups.get(group, ((), ()))
        return mean_of(tuple(dict.fromkeys((*required, *(r for alt in alternatives for r in alt)))))

    legs = [c for c in (centre(g) for g in ("leg_l", "leg_r")) if c is not None]
    # The thorax's own markers last: an upper-body set (seated, in a wheelchair) has no pelvis.
    pairs = [(centre("pelvis"), np.mean(legs, axis=0) if legs else None),
             (centre("trunk"), centre("pelvis")), (centre("head"), centre("trunk")),
             (mean_of(("IJ", "C7")), mean_of(("PX", "T10")))]
    sign = 0.0
    for high, low in pairs:
        if high is not None and low is not None:
            sign = float(np.sign(np.median((high - low)[:, axis])))
            break
    if sign == 0.0:
        sign = _floor_sign(body[seen], axis)
    name = "xyz"[axis]
    if sign == 0.0:
        marked = [g for g in ("pelvis", "leg_l", "leg_r", "trunk", "head") if centre(g) is not None]
        raise EcsAnimError(
            f"cannot tell which way is up along {name} (the body's tallest axis): the markers "
            f"found mark {', '.join(marked) or 'no body part'}, no two parts one above the "
            f"other, and no floor under the lowest markers; give --up {name} or --up -{name}")
    return name if sign > 0 else f"-{name}"


def import_c3d(path: str | Path, map_spec: str | None = None, unit: str | None = None,
               thresholds: ContactThresholds = ContactThresholds(), up: str | None = None,
               max_gap: int | None = None, fill_from: str | Path | None = None,
               trim: FrameRange | None = None, treadmill: bool = True,
               contacts: str = "detect") -> NormalizedMotion:
    """Read a C3D file and normalize it. Raises :class:`EcsAnimError` subclasses on bad input.

    ``fill_from``: a motion (.nmo or .bvh) whose parts replace the absent ones (see
    :func:`~ecs_anim.io.c3d.absent_fill.fill_absent_from`); by default they keep the neutral
    pose. ``trim``: only those frames (numbered as in the file); without it a leading rest pose
    is dropped (:func:`~ecs_anim.io.importing.leading_rest_frames`,
    ``info.rest_frames_dropped``). The file's gait events go to ``info.gait_events``;
    ``contacts="events"`` makes them the foot contacts; ``treadmill`` as in
    :func:`~ecs_anim.io.importing.normalize_clip`.
    """
    path = Path(path)
    return import_markers(path, read_c3d(path), map_spec, unit, thresholds, up, max_gap,
                          fill_from, trim, treadmill, contacts)


def import_markers(path: Path, raw: C3dMarkers, map_spec: str | None = None,
                   unit: str | None = None, thresholds: ContactThresholds = ContactThresholds(),
                   up: str | None = None, max_gap: int | None = None,
                   fill_from: str | Path | None = None, trim: FrameRange | None = None,
                   treadmill: bool = True, contacts: str = "detect") -> NormalizedMotion:
    """:func:`import_c3d` of markers already read from the file at ``path`` (a C3D, or a TRC:
    :func:`ecs_anim.io.trc.read_trc`, which holds no events or plates); arguments as there."""
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
        check_against_plates(raw, clip, extra["first_file_frame"], motion, extra)
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
        motion = fill_absent_from(motion, load_default_motion(Path(fill_from)), Path(fill_from).name,
                                  thresholds)
    return motion


def _after_trim(extra: dict[str, Any], kept: slice) -> dict[str, Any]:
    """``extra``'s frame spans (numbered as the motion's frames) after keeping only ``kept``."""
    def spans(pairs: list[list[int]]) -> list[list[int]]:
        return [[max(a, kept.start) - kept.start, min(b, kept.stop - 1) - kept.start]
                for a, b in pairs if b >= kept.start and a < kept.stop]

    gaps = dict(extra["gaps"], long_gap_frames=spans(extra["gaps"]["long_gap_frames"]))
    return dict(extra, gaps=gaps, root_frames_repaired=spans(extra["root_frames_repaired"]),
                first_file_frame=extra["first_file_frame"] + kept.start)


def canonical_clip_c3d(raw: C3dMarkers, map_spec: str | None = None, unit: str | None = None,
                       up: str | None = None, max_gap: int | None = None
                       ) -> tuple[CanonicalClip, dict[str, Any]]:
    """Markers -> canonical clip (metres, Z up) plus provenance for ``info``. ``max_gap``
    (frames): None for :data:`~ecs_anim.io.c3d.repair.DEFAULT_MAX_GAP_S` at the file's rate."""
    if max_gap is None:
        max_gap = frames_of(DEFAULT_MAX_GAP_S, raw.rate)
    # Markers never seen in the trial count as missing.
    seen: BOOL = np.asarray(raw.valid.any(axis=0))
    mmap, labels = match_labels(raw, map_spec, [bool(v) for v in seen])
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
        for members in cluster_markers(mmap):
            out = cluster_outliers(raw.positions[:, members], valid[:, members],
                                   0.015 / UNITS[unit_name])
            rejected += int(out.sum())
            valid[:, members] &= ~out
    filled, unreliable = fill_gaps(raw.positions, valid, max_gap)
    scale = UNITS[unit_name]
    mk = MarkersByRole(filled * scale, unreliable, mmap.marker, raw.anthropometry, raw.lab_model)
    if up is None:
        up = _detect_up(mk, present, mmap)
        up_reason = "detected from the markers"
    else:
        up_reason = "given with --up"
    if up not in UP_AXES:
        raise EcsAnimError(f"--up {up}: expected {', '.join(UP_AXES)}")
    if up != "z":
        mk.points = mk.points @ UP_AXES[up].T
    build, root, kept, repaired = joint_centres(mk, mmap, present)
    parts_trimmed = trimmed_part_lines(mk, mmap, present, raw.labels, root, kept)
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


__all__ = [
    "canonical_clip_c3d",
    "import_c3d",
]
