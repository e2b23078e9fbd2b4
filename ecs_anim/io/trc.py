"""OpenSim / Motion Analysis TRC marker files into the C3D import path.

A TRC ("track row column") file is text: a ``PathFileType`` line, a line naming the header's
fields (``DataRate``, ``NumFrames``, ``NumMarkers``, ``Units``, ...) and one giving their
values, a line ``Frame# Time <marker> <marker> ...`` (each name over its three columns), a line
``X1 Y1 Z1 X2 ...``, then one line a frame: its number, its time, and X, Y, Z of each marker;
an empty cell or ``NaN`` where a marker was not seen (a short row leaves its last markers
unseen). :func:`read_trc` gives the same :class:`~ecs_anim.io.c3d.reading.C3dMarkers` a C3D
file does, so labels, marker sets, units, up axis and joint centres are found as for C3D
(:func:`~ecs_anim.io.c3d.importing.canonical_clip_c3d`); :func:`import_trc` is the C3D import
(:func:`~ecs_anim.io.c3d.importing.import_markers`) without what a TRC cannot hold (gait events,
force plates, the subject's measurements).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import InputError, quoted
from ecs_anim.core.files import read_text
from ecs_anim.io.c3d.importing import import_markers
from ecs_anim.io.c3d.reading import C3dMarkers
from ecs_anim.io.contacts import ContactThresholds
from ecs_anim.io.importing import FrameRange
from ecs_anim.motion.clip import NormalizedMotion

F64 = NDArray[np.float64]

#: The header fields a TRC file must give (its second line names them, its third gives them).
REQUIRED_FIELDS = ("DataRate", "NumFrames", "NumMarkers", "Units")
#: Lines before the first frame: PathFileType, field names, field values, marker names, X1 Y1 Z1.
HEADER_LINES = 5
#: Rates a capture can have (Hz): beyond them the header is wrong.
RATE_RANGE_HZ = (0.1, 100000.0)


def _cells(line: str) -> list[str]:
    """A TRC line's cells: tab-separated as OpenSim and Cortex write them (an empty cell is an
    unseen sample), else whitespace-separated (then only a short row can leave markers out)."""
    line = line.rstrip("\r\n")
    return [c.strip() for c in line.split("\t")] if "\t" in line else line.split()


def read_trc(path: str | Path) -> C3dMarkers:
    """Read a TRC file's markers (file units and axes). Raises :class:`InputError` naming the
    file and line on any malformation: a header field missing or not a number, marker names not
    matching ``NumMarkers``, a frame row with too many cells or a cell that is no number, no
    frame, or no marker seen in any frame."""
    path = str(path)
    lines = read_text(path).splitlines()
    if not lines or not lines[0].startswith("PathFileType"):
        raise InputError(path, "expected a TRC file starting with 'PathFileType', found "
                               f"{quoted(lines[0] if lines else '', 60)}", 1)
    if len(lines) < HEADER_LINES:
        raise InputError(path, f"the header ends at line {len(lines)}: a TRC header has "
                               f"{HEADER_LINES} lines (fields, values, marker names, X1 Y1 Z1)",
                         len(lines))
    names, values = _cells(lines[1]), _cells(lines[2])
    header = dict(zip(names, values, strict=False))
    missing = [f for f in REQUIRED_FIELDS if f not in header]
    if missing:
        raise InputError(path, f"the header lacks {', '.join(missing)} (line 2 names "
                               f"{quoted(' '.join(names), 80)})", 2)
    rate = _header_number(header["DataRate"], "DataRate", path)
    n_frames = int(_header_number(header["NumFrames"], "NumFrames", path))
    n_markers = int(_header_number(header["NumMarkers"], "NumMarkers", path))
    if not RATE_RANGE_HZ[0] <= rate <= RATE_RANGE_HZ[1]:
        raise InputError(path, f"DataRate {rate:g} Hz: expected {RATE_RANGE_HZ[0]:g}-"
                               f"{RATE_RANGE_HZ[1]:g}", 3)
    labels = [c for c in _cells(lines[3])[2:] if c]
    if n_markers < 1 or len(labels) != n_markers:
        raise InputError(path, f"line 4 names {len(labels)} marker(s) where NumMarkers says "
                               f"{n_markers}", 4)
    width = 2 + 3 * n_markers
    rows: list[F64] = []
    numbers: list[int] = []
    for line_no, line in enumerate(lines[HEADER_LINES:], start=HEADER_LINES + 1):
        cells = _cells(line)
        if not any(cells):
            continue  # OpenSim writes a blank line before the first frame
        if len(cells) > width:
            raise InputError(path, f"a frame of {len(cells)} cells where {n_markers} markers "
                                   f"make {width} (Frame#, Time, X Y Z each)", line_no)
        row = np.full(width, np.nan)
        for k, cell in enumerate(cells):
            if cell and cell.lower() != "nan":
                try:
                    row[k] = float(cell)
                except ValueError:
                    raise InputError(path, f"expected a number, found {quoted(cell)} in column "
                                           f"{k + 1}", line_no) from None
        rows.append(row)
        numbers.append(line_no)
    if not rows:
        raise InputError(path, "the file holds no frame (nothing after its 5 header lines)",
                         len(lines))
    if len(rows) < n_frames:
        raise InputError(path, f"the file ends after {len(rows)} of the {n_frames} frames "
                               "NumFrames announces (truncated?)", len(lines))
    data = np.stack(rows)
    positions = data[:, 2:].reshape(len(rows), n_markers, 3)
    valid = np.all(np.isfinite(positions), axis=-1)
    if not valid.any():
        raise InputError(path, f"no marker has a sample in any of the {len(rows)} frames "
                               "(every cell is empty or NaN)")
    first = data[0, 0]
    first_frame = int(first) if math.isfinite(first) else 1
    return C3dMarkers(labels=labels, positions=np.where(valid[..., None], positions, 0.0),
                      valid=valid, rate=rate, units=header["Units"].strip().lower(),
                      first_frame=first_frame)


def _header_number(text: str, field: str, path: str) -> float:
    """A header field's value as a number, or :class:`InputError` at line 3."""
    try:
        value = float(text)
    except ValueError:
        raise InputError(path, f"{field}: expected a number, found {quoted(text)}", 3) from None
    if not math.isfinite(value) or value < 0:
        raise InputError(path, f"{field}: expected a positive number, found {quoted(text)}", 3)
    return value


def import_trc(path: str | Path, map_spec: str | None = None, unit: str | None = None,
               thresholds: ContactThresholds = ContactThresholds(), up: str | None = None,
               max_gap: int | None = None, fill_from: str | Path | None = None,
               trim: FrameRange | None = None, treadmill: bool = True) -> NormalizedMotion:
    """Read a TRC file and normalize it as :func:`~ecs_anim.io.c3d.importing.import_c3d` does a
    C3D file (same arguments; a TRC holds no gait events, so contacts are always detected).
    Raises :class:`EcsAnimError` subclasses on bad input."""
    path = Path(path)
    motion = import_markers(path, read_trc(path), map_spec, unit, thresholds, up, max_gap,
                            fill_from, trim, treadmill)
    motion.info["format_in"] = "trc"
    return motion


__all__ = ["import_trc", "read_trc"]
