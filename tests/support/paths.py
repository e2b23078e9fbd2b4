"""How far points are from a path: the measure of how well steering follows one."""

from __future__ import annotations

import numpy as np


def distance_to_polyline(points: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Each point's (k, 2) distance to the polyline ``line`` (m, 2), metres."""
    a, b = line[:-1], line[1:]
    d = b - a
    t = np.clip(np.einsum("kmi,mi->km", points[:, None] - a, d) / np.einsum("mi,mi->m", d, d),
                0.0, 1.0)
    distance: np.ndarray = np.linalg.norm(a + t[..., None] * d - points[:, None], axis=-1).min(axis=1)
    return distance
