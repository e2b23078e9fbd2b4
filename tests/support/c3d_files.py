"""Small C3D files written at test time, and byte offsets into a C3D file's parameters."""

from __future__ import annotations

import struct
import warnings
from pathlib import Path

import c3d
import numpy as np


def write_c3d(path: Path, labels: list[str], positions: np.ndarray, valid: np.ndarray | None = None,
              rate: float = 100.0, units: str = "m") -> Path:
    """A C3D file of markers (float format). positions (F, M, 3) in ``units``; invalid samples
    get residual -1."""
    writer = c3d.Writer(point_rate=rate, point_units=f"{units:4s}")
    if valid is None:
        valid = np.ones(positions.shape[:2], dtype=bool)
    frames = []
    for f in range(positions.shape[0]):  # the writer takes frames one by one (test helper only)
        points = np.zeros((positions.shape[1], 5), dtype=np.float32)
        points[:, :3] = np.where(valid[f, :, None], positions[f], 0.0)
        points[:, 3] = np.where(valid[f], 0.0, -1.0)
        frames.append((points, np.zeros((0, 0), dtype=np.float32)))
    writer.add_frames(frames)
    writer.set_point_labels(labels)
    with open(path, "wb") as out, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        writer.write(out)
    return path


def parameter_offset(data: bytes, group: str, name: str) -> int:
    """Byte offset of the value of C3D parameter ``group:name`` (Intel layout)."""
    at = (data[0] - 1) * 512 + 4
    groups: dict[int, str] = {}
    found: dict[tuple[str, str], int] = {}
    while True:
        length, group_id = struct.unpack_from("bb", data, at)
        if length == 0:
            break
        label = data[at + 2:at + 2 + abs(length)].decode("ascii")
        after_name = at + 2 + abs(length)
        step = struct.unpack_from("<h", data, after_name)[0]
        if group_id < 0:
            groups[-group_id] = label
        else:
            n_dims = data[after_name + 3]
            found[(groups.get(group_id, ""), label)] = after_name + 4 + n_dims
        if step == 0:
            break
        at = after_name + step
    return found[(group, name)]
