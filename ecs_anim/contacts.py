"""Foot-contact detection at import (paper §3: foot height and speed below thresholds).

Each foot is in contact while its ankle (heel strike, flat foot) or its toe joint (push-off) is
near its ground level and nearly still. Hysteresis keeps the state from chattering, short
contacts are dropped and short gaps filled. Everything is vectorized over frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .constraints import Activation, ConstraintSpec
from .skeleton import JOINT_INDEX as J

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class ContactThresholds:
    """Detection thresholds (all settable from ``ecs-anim import``).

    height_m : a point is low when less than this above its ground level (the 2nd percentile of
        that point's height over the clip, both feet pooled).
    speed_mps : ... and still when its horizontal speed is below this.
    release : hysteresis factor: contact ends only when height or speed exceed ``release`` times
        the thresholds.
    min_duration_s : shorter contacts are dropped; min_gap_s : shorter gaps are filled.
    ease_s : activation ramp added before and after each contact.
    """

    height_m: float = 0.05
    speed_mps: float = 0.35
    release: float = 1.5
    min_duration_s: float = 0.08
    min_gap_s: float = 0.06
    ease_s: float = 0.05

    def __post_init__(self) -> None:
        for name in ("height_m", "speed_mps", "min_duration_s", "min_gap_s", "ease_s"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"contact threshold {name} must be a finite number >= 0, got {value}")
        if not (np.isfinite(self.release) and self.release >= 1):
            raise ValueError(f"contact threshold release must be >= 1, got {self.release}")


def _box_filter(x: F64, width: int) -> F64:
    """Centred moving average along axis 0 (edges use the available samples)."""
    if width <= 1:
        return x
    pad = width // 2
    padded = np.concatenate([np.repeat(x[:1], pad, axis=0), x, np.repeat(x[-1:], pad, axis=0)])
    c = np.cumsum(np.concatenate([np.zeros((1,) + x.shape[1:]), padded]), axis=0)
    return (c[width:] - c[:-width])[: x.shape[0]] / width


def horizontal_speed(points: F64, fps: float) -> F64:
    """Horizontal speed (m/s) of points (n_frames, ..., 3), smoothed over ~50 ms. -> (n_frames, ...)."""
    if points.shape[0] < 2:
        return np.zeros(points.shape[:-1])
    velocity = np.gradient(points[..., :2], axis=0) * fps
    velocity = _box_filter(velocity, max(1, int(round(0.05 * fps)) | 1))
    return np.linalg.norm(velocity, axis=-1)


def _intervals(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Runs of True as (first, last) frame indices."""
    padded = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return [(int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2])]


def detect_contacts(positions: F64, fps: float,
                    thresholds: ContactThresholds = ContactThresholds()) -> NDArray[np.bool_]:
    """Per-frame contact flags for the left and right foot.

    ``positions`` (n_frames, N_JOINTS, 3) metres, Z up. Returns bool (n_frames, 2).
    """
    th = thresholds
    points = positions[:, [J["ankle_l"], J["ankle_r"], J["toe_l"], J["toe_r"]], :]  # (F, 4, 3)
    height = points[..., 2]
    ground = np.concatenate([
        np.repeat(np.percentile(height[:, :2], 2), 2), np.repeat(np.percentile(height[:, 2:], 2), 2)
    ])
    above = height - ground
    speed = horizontal_speed(points, fps)
    enter_pt = (above < th.height_m) & (speed < th.speed_mps)
    exit_pt = (above > th.height_m * th.release) | (speed > th.speed_mps * th.release)
    enter = enter_pt[:, :2] | enter_pt[:, 2:]
    leave = exit_pt[:, :2] & exit_pt[:, 2:]
    frames = np.arange(len(positions))[:, None]
    last_enter = np.maximum.accumulate(np.where(enter, frames, -1), axis=0)
    last_leave = np.maximum.accumulate(np.where(leave, frames, -1), axis=0)
    contact = last_enter > last_leave
    min_len = max(1, int(round(th.min_duration_s * fps)))
    min_gap = max(1, int(round(th.min_gap_s * fps)))
    for side in range(2):
        col = contact[:, side]
        for a, b in _intervals(~col):  # fill short gaps between two contacts
            if a > 0 and b < len(col) - 1 and b - a + 1 < min_gap:
                col[a:b + 1] = True
        for a, b in _intervals(col):
            if b - a + 1 < min_len:
                col[a:b + 1] = False
    return contact


def contact_constraints(contact: NDArray[np.bool_], fps: float,
                        thresholds: ContactThresholds = ContactThresholds()) -> list[ConstraintSpec]:
    """Foot-contact constraints, one per contact interval, weight 1 on every contact frame."""
    out: list[ConstraintSpec] = []
    duration = (contact.shape[0] - 1) / fps
    for side_i, side in enumerate("lr"):
        for k, (a, b) in enumerate(_intervals(contact[:, side_i])):
            t0, t1 = a / fps, b / fps
            ease_in = min(thresholds.ease_s, t0)
            ease_out = min(thresholds.ease_s, duration - t1)
            out.append(ConstraintSpec(
                name=f"contact_{side}_{k}", kind="foot_contact", segment=f"ankle_{side}",
                activation=Activation(t0 - ease_in, t1 + ease_out, ease_in, ease_out),
                chain=(f"leg_{side}", "root"), priority=100, fraction=0.0,
            ))
    return out


def contacts_from_constraints(constraints: list[ConstraintSpec], n_frames: int,
                              fps: float) -> NDArray[np.bool_]:
    """Frames where each foot's contact constraint has full weight. -> bool (n_frames, 2)."""
    t = np.arange(n_frames) / fps
    out = np.zeros((n_frames, 2), dtype=bool)
    for c in constraints:
        if c.kind == "foot_contact":
            side = 0 if c.segment.endswith("_l") else 1
            out[:, side] |= c.activation.weight(t) >= 1.0 - 1e-9
    return out
