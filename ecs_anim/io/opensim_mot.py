"""OpenSim joint angles (``.mot``, ``.sto``): read and checked, then refused in one line saying
what is missing.

A ``.mot`` holds a model's generalized coordinates over time (``pelvis_tilt``,
``hip_flexion_r``, ``knee_angle_r``, ...): a header ending at ``endheader`` (``inDegrees=yes``,
``nRows``, ``nColumns``), a line of column labels starting with ``time``, then one row a frame.
Where the joints are follows from those angles only through the model they were computed on:
its bodies' frames, its joints' offsets and the functions that couple a knee's translation to
its angle (an OpenSim ``.osim``), which import does not read. So a well-formed file is refused
naming the coordinates it holds and what to import instead (the trial's markers, ``.trc``, go
through the C3D path); a malformed one is refused naming the file and line.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import EcsAnimError, InputError, listed, quoted
from ecs_anim.core.files import read_text

F64 = NDArray[np.float64]


@dataclass
class MotCoordinates:
    """An OpenSim coordinates file: ``labels`` of the columns after ``time``, ``values``
    (n_frames, len(labels)) as written (degrees where ``in_degrees``), ``time_s`` (n_frames,)."""

    labels: list[str]
    values: F64
    time_s: F64
    in_degrees: bool
    path: str


def read_mot(path: str | Path) -> MotCoordinates:
    """Read an OpenSim ``.mot``/``.sto``. Raises :class:`InputError` naming the file and line:
    no ``endheader``, no ``time`` column, a row whose count of values is not the labels', a value
    that is no number, no frame, a column with no finite value."""
    path = str(path)
    lines = read_text(path).splitlines()
    end = next((k for k, line in enumerate(lines) if line.strip().lower() == "endheader"), None)
    if end is None:
        raise InputError(path, "no 'endheader' line: not an OpenSim .mot/.sto file", len(lines) or 1)
    header = {k.strip().lower(): v.strip().lower() for k, _, v in
              (line.partition("=") for line in lines[:end] if "=" in line)}
    rows = [(k, line.split()) for k, line in enumerate(lines[end + 1:], start=end + 2) if line.strip()]
    if not rows or rows[0][1][0].lower() != "time":
        raise InputError(path, "expected a line of column labels starting with 'time' after "
                               "endheader", rows[0][0] if rows else end + 1)
    label_line, labels = rows[0]
    data: list[F64] = []
    for line_no, cells in rows[1:]:
        if len(cells) != len(labels):
            raise InputError(path, f"a row of {len(cells)} values where the labels (line "
                                   f"{label_line}) name {len(labels)}", line_no)
        try:
            data.append(np.array([float(c) for c in cells]))
        except ValueError:
            bad = next(c for c in cells if not _is_number(c))
            raise InputError(path, f"expected a number, found {quoted(bad)}", line_no) from None
    if not data:
        raise InputError(path, "the file holds no frame (no row after the labels)", label_line)
    values = np.stack(data)
    empty = [labels[k] for k in range(values.shape[1]) if not np.isfinite(values[:, k]).any()]
    if empty:
        raise InputError(path, f"no finite value in any frame for {listed(empty, 3)}")
    return MotCoordinates(labels[1:], values[:, 1:], values[:, 0],
                          header.get("indegrees", "yes") != "no", path)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def refuse_mot(path: str | Path) -> EcsAnimError:
    """The one-line error for an OpenSim coordinates file (read first, so a malformed file is
    named with its line instead): which coordinates it holds and what import needs instead."""
    mot = read_mot(path)
    return InputError(path, f"OpenSim joint angles ({len(mot.labels)} coordinates: "
                            f"{listed(mot.labels, 3)}; {len(mot.values)} frames) need the "
                            "model's segment lengths and joint frames (its .osim), which import "
                            "does not read: import the trial's markers (.trc)")


__all__ = ["MotCoordinates", "read_mot", "refuse_mot"]
