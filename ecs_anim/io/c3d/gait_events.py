"""The trial's gait events: the file's ``EVENT`` entries in the clip's time, and the contacts its
force plates measured against the motion's."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.c3d.force_plates import plate_contacts, plate_edges
from ecs_anim.io.c3d.reading import C3dMarkers
from ecs_anim.io.contacts import gait_event_kind
from ecs_anim.io.importing import UNITS, UP_AXES, CanonicalClip, event_agreement
from ecs_anim.motion.clip import NormalizedMotion


def check_against_plates(raw: C3dMarkers, clip: CanonicalClip, first_file_frame: int,
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
    # Only the feet the markers measure: a foot filled in a neutral pose has no contacts to
    # check (normalize_clip gives it none), and its plate's edges would read as all missed.
    ankles = {"l": clip.measured[J["ankle_l"]], "r": clip.measured[J["ankle_r"]]}
    edges = [edge for edge in plate_edges(measured) if ankles.get(edge["side"], False)]
    if edges and motion.planted is not None:
        motion.info["contacts"]["plates_check"] = between_frames_agreement(
            motion.planted["on_ground"], edges, motion.fps)


def between_frames_agreement(on_ground: NDArray[np.bool_], edges: list[dict[str, Any]],
                             fps: float) -> dict[str, Any]:
    """:func:`~ecs_anim.io.importing.event_agreement` of per-frame contacts (n_frames, 2) with
    measured edges (``{"side", "kind", "time_s"}``), each contact edge taken halfway between
    the last frame on one side of it and the first on the other: a frame is on the ground
    where its instant is, so an edge lies somewhere between those two frames, and halfway is
    its best estimate (the first frame on, as ``event_agreement`` takes it, lies up to a frame
    after the edge). The reported times are the edges' own."""
    half = 0.5 / fps
    check = event_agreement(on_ground, [{**e, "time_s": e["time_s"] + half} for e in edges], fps)
    for e in check["events"]:
        e["time_s"] = round(e["time_s"] - half, 4)
    return check


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
