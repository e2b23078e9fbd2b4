"""Reading a C3D file with the ``c3d`` package: marker trajectories in file units and axes, the
events, the subject's measurements and the lab's model the file stores, and its force plates'
vertical signals (:class:`C3dMarkers`). Damaged, truncated or unlabelled files raise
:class:`~ecs_anim.core.errors.InputError`."""

from __future__ import annotations

import math
import os
import re
import struct
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import InputError, quoted
from ecs_anim.io.c3d.force_plates import ForcePlate, PlateLayout, plate_layout

F64 = NDArray[np.float64]
BOOL = NDArray[np.bool_]


C3D_BLOCK_BYTES = 512  # a C3D file is made of blocks of this size; its data ends padded to one


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


#: Per-channel parameters the ``c3d`` package reads as arrays of the standard's type: name ->
#: element type. A writer may store one as a single value or in another numeric type (Xsens
#: MVN's exporter writes ``ANALOG:OFFSET`` and ``ANALOG:SCALE`` as single 16-bit integers, with
#: no analog channel), which the package refuses, and with it the whole file.
_PER_CHANNEL = {"ANALOG:OFFSET": "int16", "ANALOG:SCALE": "float32"}
_STORED = {1: "int8", 2: "int16", 4: "float32"}


def _per_channel_as_standard(reader: Any) -> None:
    """Store each :data:`_PER_CHANNEL` parameter as the package reads it: with a dimension (a
    single value stands for every channel) and in the standard's type, its values converted
    (in the file's byte order; DEC floats, which need their own conversion, are left as
    stored)."""
    for name, kind in _PER_CHANNEL.items():
        param = reader.get(name)
        if param is None or not param.bytes or int(param.bytes_per_element) not in _STORED:
            continue
        dtypes = param._dtypes
        stored = _STORED[int(param.bytes_per_element)]
        if stored != kind and dtypes.is_dec and "float32" in (stored, kind):
            continue
        if not param.dimensions:
            param.dimensions = [1]
            param.bytes = param.bytes[:int(param.bytes_per_element)]
        if stored != kind:
            values = np.frombuffer(param.bytes, dtype=getattr(dtypes, stored))
            param.bytes = values.astype(getattr(dtypes, kind)).tobytes()
            param.bytes_per_element = np.dtype(getattr(dtypes, kind)).itemsize


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
            _per_channel_as_standard(reader)
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
