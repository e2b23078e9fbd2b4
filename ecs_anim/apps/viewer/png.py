"""Minimal PNG writing (8-bit RGB), with numpy and zlib only.

Writing goes through :func:`ecs_anim.core.files.atomic_output`: never over an existing file without
``force``, never half-written. (The tests read the files back with their own small reader.)
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.files import atomic_output

SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def encode_png(rgb: NDArray[np.uint8]) -> bytes:
    """PNG bytes of an image (height, width, 3) uint8, first row at the top."""
    rgb = np.ascontiguousarray(rgb, dtype=np.uint8)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"expected an image (height, width, 3), got shape {rgb.shape}")
    h, w = rgb.shape[:2]
    raw = np.concatenate([np.zeros((h, 1), np.uint8), rgb.reshape(h, w * 3)], axis=1)
    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    return (SIGNATURE + _chunk(b"IHDR", header) + _chunk(b"IDAT", zlib.compress(raw.tobytes(), 6))
            + _chunk(b"IEND", b""))


def write_png(path: str | Path, rgb: NDArray[np.uint8], force: bool) -> None:
    """Write ``rgb`` (height, width, 3) uint8 as a PNG; refuses to overwrite without ``force``."""
    data = encode_png(rgb)
    with atomic_output(path, force) as f:
        f.write(data)
