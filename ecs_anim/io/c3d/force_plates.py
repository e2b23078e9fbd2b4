"""Force plates of a C3D file: when each foot loaded a plate, as the plate measured it.

A force plate samples the force a foot puts on it at the analog rate (1000 Hz or more): its
vertical signal leaves its unloaded level when the foot lands and returns to it when the foot
leaves: the foot's physical touch-down and lift-off (where the whole foot is over the plate; a
foot landing or leaving partly off it is not told apart), which gait labs' foot-strike events
follow where a foot lands on a plate (Vicon Nexus and Qualisys mark them at a force threshold
of 10-20 N). Import reports these
contacts (``info.force_plates``) and how far the motion's contacts lie from them
(``info.contacts.plates_check``); they never change the contacts.

Plates of C3D types 1-4 are read (``FORCE_PLATFORM:TYPE``, ``CHANNEL``, ``CORNERS``). The
vertical signal is the plate's Fz channel (types 1, 2, 4) or the sum of its four vertical
sensors (type 3). Type 4's calibration matrix is not applied, nor does any threshold need the
force in newtons: a contact is where the signal stands more than :data:`LOAD_SHARE` of the
plate's peak load away from its unloaded level, which is the same instant in any unit.
"""

from __future__ import annotations

import struct
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.contacts import HEEL_BEHIND_ANKLE, true_runs

F64 = NDArray[np.float64]

#: The analog channels (0-based, within the plate's ``FORCE_PLATFORM:CHANNEL`` entries) whose
#: sum is the vertical force, per plate type: Fz (types 1, 2, 4: Fx, Fy, Fz, ...), the four
#: vertical sensors Fz1-Fz4 (type 3, Kistler: Fx12, Fx34, Fy14, Fy23, Fz1, Fz2, Fz3, Fz4).
VERTICAL_CHANNELS: dict[int, tuple[int, ...]] = {1: (2,), 2: (2,), 3: (4, 5, 6, 7), 4: (2,)}
#: A plate is loaded while its vertical signal stands more than this share of its peak load away
#: from the unloaded level: about 15-20 N for an adult's step, where labs place their events.
LOAD_SHARE = 0.02
#: ... and more than this many times the signal's noise while unloaded ...
LOAD_OVER_NOISE = 5.0
#: ... on a plate whose peak load is at least this many times that noise (one nobody stepped on
#: has no contact, however its noise compares with its own peak).
PEAK_OVER_NOISE = 20.0
#: A plate whose unloaded level lies further from zero than this share of its peak load was
#: never unloaded: labs zero their plates before a trial, and an amplifier's offset stays well
#: under a body's weight.
ZERO_SHARE = 1.0
#: A loaded span is a foot's step only when its load reaches this share of the plate's peak: a
#: plate measurably loaded and unloaded, not a knock, a toe's graze or a standing body's sway.
STEP_SHARE = 0.2
#: Contacts shorter than this (s) are dropped (a knock); gaps shorter than this (s) are closed.
MIN_CONTACT_S = 0.1
MIN_GAP_S = 0.02
#: The toe tip: this share of the ankle-to-toe length beyond the toe joint (the heel point is
#: contacts' :data:`~ecs_anim.io.contacts.HEEL_BEHIND_ANKLE`): the foot on a plate has either over it.
TOE_TIP_BEYOND_TOE = 0.35
#: A foot more than this (m) outside a plate's outline is not on it ...
FOOT_NEAR_PLATE_M = 0.05
#: ... and the foot on it is near it for at least this share of the span (the other foot swings
#: past it for a fraction of the stance).
FOOT_OVER_SHARE = 0.8


@dataclass(frozen=True)
class ForcePlate:
    """One force plate as the file stores it.

    number : 1-based, as ``FORCE_PLATFORM`` counts the plates.
    corners : (4, 3) the plate's outline in the file's units and axes (``FORCE_PLATFORM:CORNERS``).
    vertical : (n_samples,) the vertical-force signal in the file's analog units, one sample
        every 1 / ``rate`` seconds from the file's first frame.
    rate : the analog rate, Hz.
    """

    number: int
    corners: F64
    vertical: F64 = field(repr=False)
    rate: float


@dataclass(frozen=True)
class PlateLayout:
    """Where each plate's vertical signal is among the analog channels (read before the
    frames). channels : one tuple of 0-based analog channels per plate (their sum is the
    signal); note : why some or all plates are not read, '' when all are."""

    numbers: list[int]
    corners: list[F64]
    channels: list[tuple[int, ...]]
    note: str = ""


def _ints(param: Any) -> NDArray[np.int64]:
    """A parameter's integers, whatever their storage (1-byte, 2-byte or float)."""
    size, array = int(param.bytes_per_element), bool(param.dimensions)
    if size == 1:
        values = np.frombuffer(param.bytes, dtype=np.int8)
    elif size == 2:
        values = np.atleast_1d(param.int16_array if array else param.int16_value).reshape(-1)
    elif size == 4:
        values = np.atleast_1d(param.float_array if array else param.float_value).reshape(-1)
    else:
        raise ValueError("not a number")
    if not np.all(np.isfinite(values)):
        raise ValueError("not a finite number")
    out: NDArray[np.int64] = np.rint(values).astype(np.int64)
    return out


def plate_layout(reader: Any, analog_used: int) -> PlateLayout:
    """The plates of ``FORCE_PLATFORM`` whose vertical signal can be read. A plate of another
    type, with a channel outside the ``analog_used`` channels or without four finite corners is
    skipped, and ``note`` says why; an unreadable group gives no plate (the markers are still
    imported: plates only check the contacts)."""
    group = reader.get("FORCE_PLATFORM")
    if group is None or group.get("TYPE") is None or group.get("CHANNEL") is None:
        return PlateLayout([], [], [])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            types = _ints(group.get("TYPE"))
            used = group.get("USED")
            if used is not None:  # more TYPE entries than plates in use: the first USED
                types = types[: max(0, int(_ints(used)[0]))]
            channel_param = group.get("CHANNEL")
            per_plate = int(channel_param.dimensions[0]) if channel_param.dimensions else 0
            channels = _ints(channel_param)
            corners_param = group.get("CORNERS")
            corners = np.asarray(corners_param.float_array, dtype=np.float64).reshape(-1, 4, 3) \
                if corners_param is not None else np.zeros((0, 4, 3))
    except (AssertionError, ValueError, TypeError, AttributeError, IndexError, KeyError,
            struct.error):  # what the c3d package raises on damaged parameters
        return PlateLayout([], [], [], "FORCE_PLATFORM cannot be read")
    n = len(types)
    if n == 0:
        return PlateLayout([], [], [])
    if per_plate <= 0 or channels.size < per_plate * n:
        return PlateLayout([], [], [], "FORCE_PLATFORM:CHANNEL lists too few channels")
    channels = channels[: per_plate * n].reshape(n, per_plate)
    numbers: list[int] = []
    outlines: list[F64] = []
    chosen: list[tuple[int, ...]] = []
    skipped: list[str] = []
    for k in range(n):
        wanted = VERTICAL_CHANNELS.get(int(types[k]))
        vertical = tuple(int(channels[k, c]) - 1 for c in wanted or () if c < per_plate)
        if wanted is None:
            skipped.append(f"plate {k + 1}: type {types[k]} is not read (types 1-4 are)")
        elif len(vertical) < len(wanted):
            skipped.append(f"plate {k + 1}: {per_plate} channels for a type {types[k]} plate")
        elif min(vertical) < 0 or max(vertical) >= analog_used:
            skipped.append(f"plate {k + 1}: a channel outside the {analog_used} analog channels")
        elif k >= len(corners) or not np.all(np.isfinite(corners[k])):
            skipped.append(f"plate {k + 1}: no corners")
        else:
            numbers.append(k + 1)
            outlines.append(corners[k].copy())
            chosen.append(vertical)
    return PlateLayout(numbers, outlines, chosen, "; ".join(skipped))


def unloaded_level(signal: F64, rate: float) -> tuple[float, float]:
    """The signal's level and noise (std) while nothing stands on the plate. -> (level, noise).

    The signal is cut into 20 ms pieces; the unloaded ones sit at one end of its range (a load
    pushes it one way) and are the quiet majority there: of the two ends, the one more pieces
    lie near (within a tenth of the range), unless only one of them lies at zero (labs zero
    their plates), then the median of those pieces."""
    width = max(1, round(0.02 * rate))
    n = len(signal) // width
    if n == 0:
        return float(np.median(signal)) if len(signal) else 0.0, 0.0
    pieces = signal[: n * width].reshape(n, width)
    level = np.median(pieces, axis=1)
    low, high = float(level.min()), float(level.max())
    near = 0.1 * (high - low)
    at_low, at_high = level <= low + near, level >= high - near
    quiet = at_low if at_low.sum() >= at_high.sum() else at_high
    # Labs zero their plates: where exactly one end lies at zero (within a tenth of the range),
    # that is the unloaded one, however long a body stood loading the plate (a standing trial
    # has more loaded pieces than unloaded ones).
    zero_low, zero_high = abs(low) <= near, abs(high) <= near
    if zero_low != zero_high:
        quiet = at_low if zero_low else at_high
    noise = float(np.median(pieces[quiet].std(axis=1)))
    return float(np.median(level[quiet])), noise


@dataclass(frozen=True)
class LoadedSpan:
    """Samples ``first`` to ``last`` of a plate's signal, loaded. ``rises`` / ``falls``: the
    load crossed the threshold gradually there, so the edge is measured; not where the signal
    jumps from exactly the unloaded level to over twice the threshold (a lab that zeroed it
    below its own threshold, 50 N in one file here) or the recording starts or ends loaded."""

    first: int
    last: int
    rises: bool
    falls: bool


def loaded_spans(plate: ForcePlate) -> tuple[list[LoadedSpan], str]:
    """Each span the plate is loaded (:data:`LOAD_SHARE`, :data:`LOAD_OVER_NOISE`,
    :data:`PEAK_OVER_NOISE`), gaps under
    :data:`MIN_GAP_S` closed, spans under :data:`MIN_CONTACT_S` or whose load stays under
    :data:`STEP_SHARE` of the plate's peak dropped. -> (spans, why there
    are none: '' when the plate was simply never stepped on).

    A plate whose unloaded level lies further from zero than its peak load
    (:data:`ZERO_SHARE`) is not read: it was never unloaded (feet on it all along, as in a
    squat), so its loads cannot be told apart."""
    if len(plate.vertical) == 0 or plate.rate <= 0:
        return [], ""
    level, noise = unloaded_level(plate.vertical, plate.rate)
    load = np.abs(plate.vertical - level)
    peak = float(load.max())
    if peak == 0.0 or peak <= PEAK_OVER_NOISE * noise:
        return [], ""
    if abs(level) > ZERO_SHARE * peak:
        return [], f"plate {plate.number}: never unloaded (its lowest load is not zero)"
    threshold = max(LOAD_SHARE * peak, LOAD_OVER_NOISE * noise)
    merged: list[tuple[int, int]] = []
    for a, b in true_runs(load > threshold):
        if merged and a - merged[-1][1] - 1 < MIN_GAP_S * plate.rate:
            merged[-1] = (merged[-1][0], b)
        else:
            merged.append((a, b))
    last_sample = len(load) - 1

    def measured(edge: int, outside: int) -> bool:
        """The load crosses the threshold at ``edge`` from the sample ``outside`` it: not from
        exactly the unloaded level to over twice the threshold (a signal zeroed below some
        level, whose true edge is not in it)."""
        return bool(load[outside] > 0.0 or load[edge] <= 2.0 * threshold)

    return [LoadedSpan(a, b, a > 0 and measured(a, a - 1),
                       b < last_sample and measured(b, b + 1))
            for a, b in merged if (b - a + 1) >= MIN_CONTACT_S * plate.rate
            and load[a:b + 1].max() >= STEP_SHARE * peak], ""


def _inside(points_xy: F64, outline_xy: F64, margin: float) -> NDArray[np.bool_]:
    """Whether points (..., 2) lie within the convex outline (4, 2), at least ``margin`` inside
    (negative: that far outside still counts)."""
    edges = np.roll(outline_xy, -1, axis=0) - outline_xy  # (4, 2)
    rel = points_xy[..., None, :] - outline_xy  # (..., 4, 2)
    cross = edges[:, 0] * rel[..., 1] - edges[:, 1] * rel[..., 0]
    signed = cross / np.maximum(np.linalg.norm(edges, axis=-1), 1e-12)  # left of each edge: > 0
    twice_area = float(np.sum(outline_xy[:, 0] * np.roll(outline_xy[:, 1], -1)
                              - np.roll(outline_xy[:, 0], -1) * outline_xy[:, 1]))
    orientation = 1.0 if twice_area >= 0 else -1.0  # corners anticlockwise: inside is left
    inside: NDArray[np.bool_] = np.all(signed * orientation >= margin, axis=-1)
    return inside


def plate_contacts(plates: list[ForcePlate], plate2clip: F64, positions: F64, fps: float,
                   start_s: float) -> tuple[list[dict[str, Any]], list[str]]:
    """The foot contacts the plates measured, in the clip's seconds, one dict per loaded span,
    and a line for each plate that could not be read. -> (contacts, notes).

    ``plate2clip`` (3, 3): file units and axes to the clip's metres, Z up (a scale and the
    up-axis turn); ``positions`` (n_frames, N_JOINTS, 3) the clip's joints; ``start_s``: the
    time of the clip's frame 0 counted from the file's first frame. Each contact: ``plate``;
    ``side`` ``"l"``/``"r"``: the one foot whose heel or toe tip is within
    :data:`FOOT_NEAR_PLATE_M` of the plate's outline for :data:`FOOT_OVER_SHARE` of the span,
    else None and ``why``; ``on_s``/``off_s``; ``touch_down``/``lift_off``: whether that edge
    is measured (:class:`LoadedSpan`) and within the clip. A foot landing or leaving partly off
    the plate is not told apart: the plate loads later or unloads sooner than the foot."""
    n = len(positions)
    if n == 0:
        return [], []
    ankle = positions[:, [J["ankle_l"], J["ankle_r"]], :2]  # (F, 2, 2)
    toe = positions[:, [J["toe_l"], J["toe_r"]], :2]
    heel = ankle - HEEL_BEHIND_ANKLE * (toe - ankle)
    tip = toe + TOE_TIP_BEYOND_TOE * (toe - ankle)
    foot = np.stack([heel, tip], axis=2)  # (F, 2 sides, 2 points, 2)
    duration = (n - 1) / fps
    contacts: list[dict[str, Any]] = []
    notes: list[str] = []
    for plate in plates:
        outline = (plate.corners @ plate2clip.T)[:, :2]
        spans, why = loaded_spans(plate)
        if why:
            notes.append(why)
        for span in spans:
            on_s = span.first / plate.rate - start_s
            off_s = (span.last + 1) / plate.rate - start_s
            if off_s <= 0 or on_s >= duration:
                continue
            frames = slice(max(0, round(on_s * fps)), min(n, round(off_s * fps) + 1))
            near = _inside(foot[frames], outline, -FOOT_NEAR_PLATE_M).any(axis=-1)  # (f, 2)
            over = near.mean(axis=0) >= FOOT_OVER_SHARE
            contact: dict[str, Any] = {
                "plate": plate.number, "side": None, "on_s": round(on_s, 4),
                "off_s": round(off_s, 4), "touch_down": False, "lift_off": False}
            if int(over.sum()) != 1:
                contact["why"] = "both feet over the plate" if over.all() else "no foot over the plate"
            else:
                contact["side"] = "lr"[int(np.argmax(over))]
                contact["touch_down"] = span.rises and on_s >= 0
                contact["lift_off"] = span.falls and off_s <= duration
            contacts.append(contact)
    return contacts, notes


def plate_edges(contacts: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The plates' measured touch-downs and lift-offs (``touch_down``, ``lift_off``) as gait
    events (``{"side", "kind", "time_s"}``), on the plates measurably loaded and unloaded: with
    a step whose touch-down and lift-off are both measured. A plate a body stepped on and stood
    on to the end (a standing trial) has no step to check against."""
    stepped = {c["plate"] for c in contacts if c["touch_down"] and c["lift_off"]}
    events: list[dict[str, Any]] = []
    for c in contacts:
        if c["plate"] not in stepped:
            continue
        if c["touch_down"]:
            events.append({"side": c["side"], "kind": "strike", "time_s": c["on_s"]})
        if c["lift_off"]:
            events.append({"side": c["side"], "kind": "off", "time_s": c["off_s"]})
    return events
