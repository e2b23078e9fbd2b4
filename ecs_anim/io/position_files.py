"""Reading joint-position files: ``.npy`` and ``.npz`` arrays (frames, joints, 3), MediaPipe's
landmarks as JSON or CSV. Each reader returns a :class:`PositionFile`; a malformed file is one
:class:`~ecs_anim.core.errors.InputError` naming the file and the place (array, frame, row)."""

from __future__ import annotations

import csv
import json
import math
import zipfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import InputError, listed

F64 = NDArray[np.float64]

#: The suffixes joint positions are read from.
POSITION_SUFFIXES = (".npy", ".npz", ".json", ".csv")
#: ``.npz`` arrays that may hold the positions, in the order they are looked for.
NPZ_POSITION_KEYS = ("positions", "joints", "joints3d", "joints_3d", "keypoints3d",
                     "keypoints_3d", "kps3d", "poses_3d", "pose_world_landmarks", "reconstruction")
#: ``.npz`` and JSON entries that give the frame rate.
FPS_KEYS = ("fps", "frame_rate", "framerate", "mocap_framerate", "mocap_frame_rate")
#: JSON landmark lists, as MediaPipe's results name them (world ones first).
JSON_LANDMARK_KEYS = ("pose_world_landmarks", "world_landmarks", "landmarks", "pose_landmarks",
                      "keypoints", "joints")
#: CSV columns of the long form (one landmark a row), and columns giving time.
CSV_FRAME_COLUMNS = ("frame", "frame_index", "frame_idx")
CSV_JOINT_COLUMNS = ("landmark", "landmark_index", "joint", "joint_index", "index", "id")
CSV_TIME_COLUMNS = {"time": 1.0, "time_s": 1.0, "timestamp": 1.0, "timestamp_s": 1.0,
                    "timestamp_ms": 0.001, "time_ms": 0.001}


@dataclass(frozen=True)
class PositionFile:
    """What a positions file holds: ``positions`` (n_frames, n_joints, 3) in the file's unit
    and axes, NaN where a joint is missing; ``fps`` when the file gives it; ``names`` the joints'
    names when it gives them; ``form`` how it was read, for the import's line; ``layout`` the
    layout an export of ours names in its ``.npz``."""

    positions: F64
    fps: float | None
    names: tuple[str, ...] | None
    form: str
    layout: str | None = None


def read_positions(path: Path) -> PositionFile:
    """Read a ``.npy``, ``.npz``, ``.json`` or ``.csv`` positions file; raises
    :class:`InputError` naming the file and the place of the first problem."""
    suffix = path.suffix.lower()
    try:
        if suffix == ".npy":
            found = _from_array(path, _load_npy(path), "array", None, None, "npy array")
        elif suffix == ".npz":
            found = _read_npz(path)
        elif suffix == ".json":
            found = _read_json(path)
        elif suffix == ".csv":
            found = _read_csv(path)
        else:
            raise InputError(path, f"unsupported suffix {path.suffix!r} for joint positions "
                                   f"(expected {', '.join(POSITION_SUFFIXES)})")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(path, f"cannot read: {exc}") from None
    return found


def _load_npy(path: Path) -> Any:
    try:
        return np.load(path, allow_pickle=False)
    except ValueError as exc:  # a pickled object array, or a damaged header
        raise InputError(path, f"not a plain numeric .npy array ({exc})") from None


def _from_array(path: Path, array: Any, where: str, fps: float | None,
                names: tuple[str, ...] | None, form: str) -> PositionFile:
    """``array`` (frames, joints, 3), or (frames, 3 * joints), checked: numbers, frames, not
    NaN everywhere."""
    arr = np.asarray(array)
    if arr.dtype.kind not in "fiu":
        raise InputError(path, f"{where}: holds {arr.dtype} values, expected numbers")
    if arr.ndim == 2 and arr.shape[1] % 3 == 0 and arr.shape[1] > 3:
        arr = arr.reshape(arr.shape[0], -1, 3)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise InputError(path, f"{where}: shape {arr.shape}, expected (frames, joints, 3) "
                               "or (frames, 3 x joints)")
    if arr.shape[0] < 2:
        raise InputError(path, f"{where}: {arr.shape[0]} frame(s); a motion needs at least 2")
    if arr.shape[1] < 1:
        raise InputError(path, f"{where}: no joints")
    positions = arr.astype(np.float64)
    if np.isinf(positions).any():
        frame = int(np.argwhere(np.isinf(positions))[0][0])
        raise InputError(path, f"{where}: an infinite value at frame {frame}")
    if not np.isfinite(positions).any():
        raise InputError(path, f"{where}: NaN everywhere, no joint position in any frame")
    if names is not None and len(names) != positions.shape[1]:
        raise InputError(path, f"{where}: {len(names)} joint names for {positions.shape[1]} joints")
    return PositionFile(positions, fps, names, form)


def _fps_value(path: Path, value: Any, where: str) -> float:
    try:
        fps = float(np.asarray(value).reshape(-1)[0])
    except (TypeError, ValueError, IndexError):
        raise InputError(path, f"{where}: the frame rate {value!r} is not a number") from None
    if not (math.isfinite(fps) and fps > 0):
        raise InputError(path, f"{where}: the frame rate {fps:g} is not a positive number")
    return fps


def _read_npz(path: Path) -> PositionFile:
    try:
        archive = np.load(path, allow_pickle=False)
    except (ValueError, zipfile.BadZipFile) as exc:
        raise InputError(path, f"not a readable .npz archive ({exc})") from None
    with archive:
        keys = list(archive.files)
        if "poses" in keys and "betas" in keys and not any(k in keys for k in NPZ_POSITION_KEYS):
            raise InputError(path, "holds SMPL parameters (poses, betas), not joint positions")
        key = next((k for k in NPZ_POSITION_KEYS if k in keys), None)
        if key is None:
            shaped = [k for k in keys if archive[k].ndim == 3 and archive[k].shape[-1] == 3]
            if len(shaped) != 1:
                raise InputError(path, f"no array of joint positions: expected one named "
                                       f"{listed(NPZ_POSITION_KEYS, 4)}, or a single (frames, "
                                       f"joints, 3) array; found {listed(keys) or 'none'}")
            key = shaped[0]
        fps_key = next((k for k in FPS_KEYS if k in keys), None)
        fps = _fps_value(path, archive[fps_key], f"array {fps_key!r}") if fps_key else None
        names = None
        if "joint_names" in keys or ("joints" in keys and key != "joints"):
            raw = archive["joint_names" if "joint_names" in keys else "joints"]
            if raw.dtype.kind == "U":
                names = tuple(str(n) for n in raw.reshape(-1))
        found = _from_array(path, archive[key], f"array {key!r}", fps, names, f"npz array {key!r}")
        if "layout" in keys and archive["layout"].dtype.kind == "U":
            found = replace(found, layout=str(archive["layout"]))
        return found


def _landmark_xyz(path: Path, item: Any, where: str) -> list[float]:
    """One landmark: ``{"x":, "y":, "z": ...}`` (MediaPipe's Landmark) or ``[x, y, z]``."""
    if isinstance(item, dict):
        if not all(k in item for k in "xyz"):
            raise InputError(path, f"{where}: a landmark without x, y and z ({listed(item)})")
        values = [item["x"], item["y"], item["z"]]
    elif isinstance(item, list) and len(item) >= 3:
        values = item[:3]
    else:
        raise InputError(path, f"{where}: expected a landmark {{x, y, z}} or [x, y, z], found "
                               f"{json.dumps(item)[:40]}")
    out = []
    for v in values:
        if v is None:
            out.append(math.nan)
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            out.append(float(v))
        else:
            raise InputError(path, f"{where}: {json.dumps(v)[:20]} is not a number")
    return out


def _frame_landmarks(path: Path, frame: Any, where: str) -> list[Any] | None:
    """A frame's landmark list: a list, or an object holding one under a MediaPipe name (its
    first pose when it holds several); None for a frame with no pose detected."""
    if isinstance(frame, dict):
        key = next((k for k in JSON_LANDMARK_KEYS if k in frame), None)
        if key is None:
            raise InputError(path, f"{where}: no landmarks (expected one of "
                                   f"{listed(JSON_LANDMARK_KEYS, 3)})")
        frame = frame[key]
    if not isinstance(frame, list):
        raise InputError(path, f"{where}: expected a list of landmarks")
    if frame and isinstance(frame[0], list) and frame[0] and not isinstance(frame[0][0], (int, float)):
        frame = frame[0]  # several poses: the first
    return frame or None


def _read_json(path: Path) -> PositionFile:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise InputError(path, f"not JSON: {exc.msg}", exc.lineno) from None
    fps = None
    names = None
    if isinstance(data, dict):
        fps_key = next((k for k in FPS_KEYS if k in data), None)
        fps = _fps_value(path, data[fps_key], f"{fps_key!r}") if fps_key else None
        if isinstance(data.get("joint_names"), list):
            names = tuple(str(n) for n in data["joint_names"])
        frames = next((data[k] for k in ("frames", *JSON_LANDMARK_KEYS) if k in data), None)
        if frames is None:
            raise InputError(path, "expected a list of frames, or an object with 'frames'")
    else:
        frames = data
    if not isinstance(frames, list):
        raise InputError(path, "the frames are not a list")
    rows: list[list[list[float]] | None] = []
    times: list[float] = []
    for f, frame in enumerate(frames):
        if isinstance(frame, dict) and "timestamp_ms" in frame:
            times.append(float(frame["timestamp_ms"]) / 1000.0)
        landmarks = _frame_landmarks(path, frame, f"frame {f}")
        rows.append(None if landmarks is None else
                    [_landmark_xyz(path, item, f"frame {f}, landmark {k}")
                     for k, item in enumerate(landmarks)])
    counts = {len(r) for r in rows if r is not None}
    if len(counts) > 1:
        first = next(r for r in rows if r is not None)
        bad = next(f for f, r in enumerate(rows) if r is not None and len(r) != len(first))
        raise InputError(path, f"frame {bad}: {len(rows[bad] or [])} landmarks where frame 0 "
                               f"with a pose has {len(first)}")
    n_joints = counts.pop() if counts else 0
    array = np.full((len(rows), n_joints, 3), np.nan)
    for f, row in enumerate(rows):
        if row is not None:
            array[f] = row
    if fps is None and len(times) == len(frames) and len(times) > 1:
        step = float(np.median(np.diff(times)))
        fps = 1.0 / step if step > 0 else None
    return _from_array(path, array, "the landmarks", fps, names, "JSON landmarks")


def _read_csv(path: Path) -> PositionFile:
    with path.open(newline="", encoding="utf-8") as f:
        table = list(csv.reader(f))
    if not table:
        raise InputError(path, "empty file, no header row")
    header = [h.strip().lower() for h in table[0]]
    rows = [r for r in table[1:] if any(c.strip() for c in r)]
    for k, row in enumerate(rows):
        if len(row) != len(header):
            raise InputError(path, f"{len(row)} columns where the header has {len(header)}", k + 2)

    def number(row: list[str], col: int, line: int) -> float:
        text = row[col].strip()
        if text in ("", "nan", "NaN"):
            return math.nan
        try:
            return float(text)
        except ValueError:
            raise InputError(path, f"column {header[col]!r}: {text[:20]!r} is not a number",
                             line) from None

    time_col = next((header.index(c) for c in CSV_TIME_COLUMNS if c in header), None)
    frame_col = next((header.index(c) for c in CSV_FRAME_COLUMNS if c in header), None)
    joint_col = next((header.index(c) for c in CSV_JOINT_COLUMNS if c in header), None)
    if frame_col is not None and joint_col is not None and all(a in header for a in "xyz"):
        xyz = [header.index(a) for a in "xyz"]
        keys = [(int(number(r, frame_col, k + 2)), int(number(r, joint_col, k + 2)))
                for k, r in enumerate(rows)]
        frames_seen = sorted({frame for frame, _ in keys})
        n_joints = max(j for _, j in keys) + 1 if keys else 0
        array = np.full((len(frames_seen), n_joints, 3), np.nan)
        where = {frame: i for i, frame in enumerate(frames_seen)}
        for k, ((frame, joint), row) in enumerate(zip(keys, rows, strict=True)):
            array[where[frame], joint] = [number(row, c, k + 2) for c in xyz]
        form = "CSV, one landmark a row"
    else:
        triples = [k for k in range(len(header) - 2)
                   if _axis(header[k]) == "x" and _axis(header[k + 1]) == "y"
                   and _axis(header[k + 2]) == "z"]
        if not triples:
            raise InputError(path, "no x, y, z columns: expected a header naming them (x0,y0,z0,"
                                   "... or nose_x,nose_y,nose_z,... or frame,landmark,x,y,z)", 1)
        array = np.array([[[number(r, k + a, line + 2) for a in range(3)] for k in triples]
                          for line, r in enumerate(rows)]).reshape(len(rows), len(triples), 3)
        names = tuple(header[k][:-2] if _axis(header[k]) and len(header[k]) > 2
                      and header[k][-2] in "_. " else "" for k in triples)
        form = "CSV, one frame a row"
        times = [number(r, time_col, k + 2) for k, r in enumerate(rows)] if time_col is not None else None
        fps = _fps_from_times(times, CSV_TIME_COLUMNS[header[time_col]] if time_col is not None else 1.0)
        return _from_array(path, array, "the table", fps,
                           names if all(names) and len(set(names)) == len(names) else None, form)
    return _from_array(path, array, "the table", None, None, form)


def _fps_from_times(times: list[float] | None, seconds_per_unit: float) -> float | None:
    if not times or len(times) < 2:
        return None
    step = float(np.nanmedian(np.diff(times))) * seconds_per_unit
    return 1.0 / step if step > 0 else None


def _axis(column: str) -> str:
    """``"nose_x"`` / ``"x12"`` / ``"x"`` -> ``"x"``; anything else -> ``""``."""
    if column in ("x", "y", "z"):
        return column
    if column[-1:] in ("x", "y", "z") and column[-2:-1] in ("_", ".", " "):
        return column[-1]
    if column[:1] in ("x", "y", "z") and column[1:].lstrip("_").isdigit():
        return column[0]
    return ""


__all__ = ["POSITION_SUFFIXES", "PositionFile", "read_positions"]
