"""Foot-contact detection at import (paper §3: foot height and speed below thresholds).

Each foot is in contact while its ankle (heel strike, flat foot) or its toe joint (push-off) is
near its ground level and nearly still. Hysteresis keeps the state from chattering, short
contacts are dropped and short gaps filled. The contact's edges are then moved to the foot's
touch-down (the heel lands) and lift-off (the ball leaves the ground), where gait events are.
Everything is vectorized over frames but those edges (a loop over contacts).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import UsageError
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.motion.constraints import Activation, ConstraintSpec

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class ContactThresholds:
    """Detection thresholds. ``ecs-anim import`` sets three: ``height_m``
    (``--contact-height``), ``speed_mps`` (``--contact-speed``) and ``min_duration_s``
    (``--contact-min-duration``); the others from Python (``import_bvh`` and ``import_c3d``:
    ``thresholds=``).

    height_m : a point (heel = ankle joint, ball = toe joint) is low when less than this above
        the local ground under it, for a body of 0.8 m leg (scaled by the body's leg): the
        lowest that point of either foot comes within ``ground_radius`` legs horizontally and
        ``ground_window_s`` seconds.
    speed_mps : ... and still when its speed (filtered over ``filter_s`` seconds) is below this;
        None: relative to the body and the clip's own motion, ``SPEED_OF_MOTION`` times how fast
        that point moves when it moves (its 90th percentile), kept between
        ``SPEED_PER_LEG`` legs per second (each bound).
    release : hysteresis factor: a part's contact ends only when its height or speed exceed
        ``release`` times the thresholds.
    min_duration_s : shorter contacts are dropped; min_gap_s : shorter gaps are filled.
    ease_s : activation ramp added before and after each contact.
    edge_height_m, edge_swing_share, edge_max_s : where a contact's touch-down and lift-off lie
        (:func:`touch_down_to_lift_off`): the heel point (or the toe joint, landing on the
        ball) has come down to within ``edge_height_m`` (for a 0.8 m leg, scaled by the body's)
        of the lowest it comes as the foot lands; the toe joint (or the heel point, the last to
        leave) moves horizontally faster than ``edge_swing_share`` of its swing speed. Each
        edge of a stillness contact moves at most ``edge_max_s``. Heights and speeds are first
        smoothed over ``edge_filter_s`` seconds (centred, no lag).
    """

    height_m: float = 0.05
    speed_mps: float | None = None
    release: float = 1.5
    min_duration_s: float = 0.08
    min_gap_s: float = 0.06
    ease_s: float = 0.05
    filter_s: float = 0.05
    ground_window_s: float = 1.5
    ground_radius: float = 0.15
    edge_height_m: float = 0.0025
    edge_swing_share: float = 0.28
    edge_max_s: float = 0.1
    edge_filter_s: float = 0.03

    def __post_init__(self) -> None:
        for name in ("height_m", "speed_mps", "min_duration_s", "min_gap_s", "ease_s",
                     "filter_s", "ground_window_s", "ground_radius", "edge_height_m",
                     "edge_swing_share", "edge_max_s", "edge_filter_s"):
            value = getattr(self, name)
            if value is None and name == "speed_mps":
                continue
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value >= 0):
                raise UsageError(f"contact threshold {name} must be a finite number >= 0, got {value}")
        if not (np.isfinite(self.release) and self.release >= 1):
            raise UsageError(f"contact threshold release must be >= 1, got {self.release}")


#: The automatic speed threshold: this fraction of the point's swing speed (its fastest within
#: ``STRIDE_S`` either side) ...
SPEED_OF_MOTION = 0.15
STRIDE_S = 0.6
#: ... kept between these many legs per second, the upper bound raised by that fraction of the
#: swing speed above ``SPRINT_SWING_PER_LEG`` legs per second (a run faster than a jog: its
#: stance foot rolls faster than a walker's slides).
SPEED_PER_LEG = (0.4, 0.45)
SPRINT_SWING_PER_LEG = 8.0
#: A part's contact ends, whatever the hysteresis, above this many legs per second.
RELEASE_PER_LEG = 0.55
#: A leg that stays within this (m) of one pose relative to the pelvis is a fill, not a capture.
RIGID_LEG_M = 0.0005
#: Leg length (m) the height threshold is given for.
REFERENCE_LEG_M = 0.8
#: How far (m, for a 0.8 m leg) the ankle stands above its lowest in the stance when the heel
#: lands: the foot still pitched up, the ankle sinks as it rolls flat (median 5.6 mm at the 366
#: touch-downs of the 21 dev BVH files; 0-29 mm, 10-90 %). Where the toe is a fill that follows
#: the ankle, a touch-down is seen on the ankle within this of the heel's own threshold: on those
#: files, as Human3.6M joints, 516 of 758 touch-downs within one frame of the BVH import's
#: (437 of 760 with the heel's 2.5 mm alone; 510 at 4 or 6 mm).
ANKLE_RISE_AT_STRIKE_M = 0.005


def box_filter(x: F64, width: int) -> F64:
    """Centred moving average along axis 0 (edges use the available samples)."""
    if width <= 1:
        return x
    pad = width // 2
    padded = np.concatenate([np.repeat(x[:1], pad, axis=0), x, np.repeat(x[-1:], pad, axis=0)])
    c = np.cumsum(np.concatenate([np.zeros((1,) + x.shape[1:]), padded]), axis=0)
    mean: F64 = (c[width:] - c[:-width])[: x.shape[0]] / width
    return mean


def frames_of(seconds: float, fps: float) -> int:
    """The number of frames (at least 1) spanning ``seconds`` at ``fps`` Hz (Python's rounding:
    a half frame rounds to even, 0.05 s at 50 Hz is 2 frames)."""
    return max(1, round(seconds * fps))


def _width(seconds: float, fps: float) -> int:
    """An odd number of frames spanning about ``seconds``."""
    return frames_of(seconds, fps) | 1


def horizontal_speed(points: F64, fps: float, filter_s: float = 0.05) -> F64:
    """Horizontal speed (m/s) of points (n_frames, ..., 3), smoothed over ``filter_s``.
    -> (n_frames, ...)."""
    if points.shape[0] < 2:
        return np.zeros(points.shape[:-1])
    velocity = np.gradient(points[..., :2], axis=0) * fps
    velocity = box_filter(velocity, _width(filter_s, fps))
    speed: F64 = np.linalg.norm(velocity, axis=-1)
    return speed


def speed(points: F64, fps: float, filter_s: float = 0.03) -> F64:
    """Speed (m/s) of points (n_frames, ..., 3), velocity smoothed over ``filter_s`` seconds.
    -> (n_frames, ...)."""
    if points.shape[0] < 2:
        return np.zeros(points.shape[:-1])
    velocity = box_filter(np.gradient(points, axis=0) * fps, _width(filter_s, fps))
    speed: F64 = np.linalg.norm(velocity, axis=-1)
    return speed


def local_ground(points: F64, fps: float, window_s: float, radius_m: float,
                 still: NDArray[np.bool_]) -> F64:
    """The ground under each point at each frame: the lowest any of the points stood still
    (``still``) within ``radius_m`` horizontally of it and ``window_s`` seconds before or after;
    -inf where none did (a swing foot far from any footprint: no ground known under it).

    points (n_frames, K, 3) metres, Z up (e.g. both heels), still (n_frames, K). Returns
    (n_frames, K) heights. The loop runs over the window's frame offsets and the points, never
    over frames."""
    n, k = points.shape[:2]
    reach = frames_of(window_s, fps)
    ground = np.where(still, points[..., 2], np.inf)
    z_still = np.where(still, points[..., 2], np.inf)
    step = max(1, reach // 120)  # at most ~240 offsets, whatever the rate
    for offset in range(-reach, reach + 1, step):
        if offset == 0 or abs(offset) >= n:
            continue
        a = slice(max(0, -offset), n - max(0, offset))  # frames t
        b = slice(max(0, offset), n - max(0, -offset))  # frames t + offset
        for j in range(k):
            near = np.linalg.norm(points[b, :, :2] - points[a, j:j + 1, :2], axis=-1) < radius_m
            z = np.where(near, z_still[b], np.inf).min(axis=1)
            ground[a, j] = np.minimum(ground[a, j], z)
    ground[~np.isfinite(ground)] = -np.inf
    return ground


def true_runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Runs of True as (first, last) frame indices."""
    padded = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return [(int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def _hysteresis(enter: NDArray[np.bool_], leave: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """On from a frame where ``enter`` holds until one where ``leave`` does (columns apart)."""
    frames = np.arange(len(enter))[:, None]
    last_enter = np.maximum.accumulate(np.where(enter, frames, -1), axis=0)
    last_leave = np.maximum.accumulate(np.where(leave, frames, -1), axis=0)
    on: NDArray[np.bool_] = last_enter > last_leave
    return on


def _clean(flags: NDArray[np.bool_], fps: float, th: ContactThresholds) -> NDArray[np.bool_]:
    """Short gaps between two contacts filled, then short contacts dropped (per column). A
    contact or gap at the clip's first or last frame is kept whatever its length: the clip
    cuts it, so how long it lasts is not known (a clip starting late in a stance keeps it)."""
    flags = flags.copy()
    min_len = frames_of(th.min_duration_s, fps)
    min_gap = frames_of(th.min_gap_s, fps)
    for side in range(flags.shape[1]):
        col = flags[:, side]
        for a, b in true_runs(~col):
            if a > 0 and b < len(col) - 1 and b - a + 1 < min_gap:
                col[a:b + 1] = True
        for a, b in true_runs(col):
            if a > 0 and b < len(col) - 1 and b - a + 1 < min_len:
                col[a:b + 1] = False
    return flags


@dataclass
class FootContacts:
    """Which part of each foot is planted, per frame: bool (n_frames, 2) each, left/right.

    heel : the ankle joint still and low; ball : the toe joint still and low; foot : either
    (the whole-foot contact the tick plants); on_ground : from touch-down (the heel lands) to
    lift-off (the ball leaves the ground), :func:`touch_down_to_lift_off`: the foot's
    stillness contacts with their edges moved to where gait events are. heel, ball and foot
    hold only within on_ground. speed_threshold_mps : (2,) the heel's and the ball's threshold
    used. Arrays ``height`` (n_frames, 4): heel l, heel r, ball l, ball r above their local
    ground (m); ``speed`` (n_frames, 4) their speeds (m/s).
    """

    heel: NDArray[np.bool_]
    ball: NDArray[np.bool_]
    foot: NDArray[np.bool_]
    on_ground: NDArray[np.bool_]
    speed_threshold_mps: tuple[float, float]
    height: F64
    speed: F64


def leg_of(positions: F64) -> float:
    """Median thigh + shank (m), both sides averaged, of joint positions (n_frames, N_JOINTS, 3)."""
    total = 0.0
    for s in "lr":
        hip, knee, ankle = (positions[:, J[f"{p}_{s}"]] for p in ("hip", "knee", "ankle"))
        total += float(np.median(np.linalg.norm(knee - hip, axis=-1)
                                 + np.linalg.norm(ankle - knee, axis=-1)))
    return 0.5 * total


def stride_peak(speed: F64, fps: float) -> F64:
    """How fast each point moves when it swings: its fastest within :data:`STRIDE_S` seconds
    either side of each frame. ``speed`` (n_frames, ...) -> (n_frames, ...). The loop runs over
    offsets of the window, not frames."""
    n = len(speed)
    swing = speed.copy()
    reach = min(n - 1, frames_of(STRIDE_S, fps)) if n else 0
    step = max(1, reach // 60)
    for offset in range(step, reach + 1, step):
        swing[offset:] = np.maximum(swing[offset:], speed[:-offset])
        swing[:-offset] = np.maximum(swing[:-offset], speed[offset:])
    return swing


def cycle_speed_limit(speed: F64, fps: float, leg: float) -> F64:
    """The stillness threshold of each point at each frame, relative to its own cycle: the
    stance is the slow phase of a stride, slow next to that stride's swing. -> (n_frames, K)
    m/s.

    ``speed`` (n_frames, K) m/s. :data:`SPEED_OF_MOTION` times the point's swing speed
    (:func:`stride_peak`), kept within :data:`SPEED_PER_LEG` legs per second, the upper bound
    raised for swings faster than :data:`SPRINT_SWING_PER_LEG`: a sprint (swing over 15 m/s)
    keeps its short stances while a walk keeps the walker's threshold, and a body standing or
    shuffling (no swing) the floor's."""
    swing = stride_peak(speed, fps)
    upper = SPEED_PER_LEG[1] * leg + SPEED_OF_MOTION * np.maximum(swing - SPRINT_SWING_PER_LEG * leg, 0.0)
    limit: F64 = np.clip(SPEED_OF_MOTION * swing, SPEED_PER_LEG[0] * leg, upper)
    return limit


def detect_foot_contacts(positions: F64, fps: float,
                         thresholds: ContactThresholds = ContactThresholds(),
                         toes_follow_ankle: bool = False) -> FootContacts:
    """Heel, ball and whole-foot contacts from the foot's own stillness over any ground.

    ``positions`` (n_frames, N_JOINTS, 3) metres, Z up. A point (heel: ankle joint, ball: toe
    joint) is planted while it is still (speed under the threshold, see
    :class:`ContactThresholds`) and low (under ``height_m`` above :func:`local_ground`: the
    lowest the points come nearby, so a step, a box or stairs are ground too), with hysteresis;
    the foot is planted while either is. Vectorized over frames.

    ``toes_follow_ankle``: the toe joints were filled in rigidly with the ankles (a positions
    layout without toes), so the heel point and the toe joint rise and sink with the ankle and
    the foot's pitch is not known: a touch-down is where the ankle comes down to within
    ``edge_height_m`` plus :data:`ANKLE_RISE_AT_STRIKE_M` of its lowest.
    """
    th = thresholds
    if toes_follow_ankle:
        th = replace(th, edge_height_m=th.edge_height_m + ANKLE_RISE_AT_STRIKE_M)
    points = positions[:, [J["ankle_l"], J["ankle_r"], J["toe_l"], J["toe_r"]], :]  # (F, 4, 3)
    leg = leg_of(positions) if len(positions) else REFERENCE_LEG_M
    radius = th.ground_radius * leg
    v = horizontal_speed(points, fps, th.filter_s)  # rising or sinking, a low point stays put
    if th.speed_mps is not None:
        limit4 = np.full(v.shape, float(th.speed_mps))
    else:
        limit4 = cycle_speed_limit(v, fps, leg)
    still = v < limit4
    ground = np.concatenate([
        local_ground(points[:, :2], fps, th.ground_window_s, radius, still[:, :2]),
        local_ground(points[:, 2:], fps, th.ground_window_s, radius, still[:, 2:])], axis=1)
    above = points[..., 2] - ground
    height = th.height_m * leg / REFERENCE_LEG_M
    enter = (above < height) & (v < limit4)
    leave = (above > height * th.release) | (v > np.minimum(
        limit4 * th.release, np.maximum(RELEASE_PER_LEG * leg, limit4)))
    # Hysteresis both ways in time: a contact starts where the point first drops under the
    # release thresholds before it is still, as it ends where it rises over them after.
    part = _clean(_hysteresis(enter, leave), fps, th)
    part &= ~leave  # a filled gap plants no part that moves (the whole foot may bridge it)
    heel, ball = part[:, :2], part[:, 2:]
    planted = _clean(heel | ball, fps, th)
    on_ground = touch_down_to_lift_off(points, planted, fps, leg, th)
    limit = (float(np.median(limit4[:, :2])), float(np.median(limit4[:, 2:]))) if len(v) \
        else (0.0, 0.0)
    return FootContacts(heel & planted & on_ground, ball & planted & on_ground,
                        planted & on_ground, on_ground, limit, above, v)


#: The heel point a touch-down is found on: this fraction of the ankle-to-toe vector behind the
#: ankle joint, on the line through both (about over the heel's contact point for adult and
#: child proportions). The foot rolls onto the heel and then about it, so that point comes down
#: to the ground when the heel lands, while the ankle still sinks until the foot is flat.
HEEL_BEHIND_ANKLE = 0.25
#: A stillness contact's frames next to it that are low (within this of the contact's lowest, m
#: for a 0.8 m leg) stay on the ground where moving its edges would leave both feet up.
LOW_M = 0.015


def touch_down_to_lift_off(points: F64, planted: NDArray[np.bool_], fps: float, leg: float,
                           thresholds: ContactThresholds) -> NDArray[np.bool_]:
    """Each foot on the ground from touch-down to lift-off: its stillness contacts with their
    edges moved to where the foot lands and leaves the ground (:func:`contact_edges`): a frame
    is on the ground where its instant lies from touch-down up to lift-off, so each edge lies
    between the last frame off and the first on. -> bool (n_frames, 2).

    ``points`` (n_frames, 4, 3): ankle l, r, toe l, r; ``planted`` (n_frames, 2): the stillness
    contacts. A moved edge never leaves both feet up where one was low (a stance foot sinking
    or rising over uneven ground is not in the air): there the stillness contact, extended over
    the frames next to it where the ankle (before it) or the toe joint (after it) is within
    :data:`LOW_M` of its lowest in the contact, stays on the ground."""
    th = thresholds
    n = len(points)
    most = round(th.edge_max_s * fps)
    low_m = LOW_M * leg / REFERENCE_LEG_M
    out = np.zeros_like(planted)
    widest = planted.copy()  # the contacts over every low frame next to them
    nowhere = np.zeros(n, dtype=bool)
    edges = contact_edges(points, planted, fps, leg, th)
    for side in range(planted.shape[1]):
        col = planted[:, side]
        ankle_z, toe_z = points[:, side, 2], points[:, 2 + side, 2]
        for (a, b), (start, stop) in zip(true_runs(col), edges[side], strict=True):
            out[int(np.ceil(start)):int(np.ceil(stop)), side] = True
            ankle_low = ankle_z < ankle_z[a:b + 1].min() + low_m
            toe_low = toe_z < toe_z[a:b + 1].min() + low_m
            widest[_edge_back(col, a, b, ankle_low | col, nowhere, most):
                   _edge_on(col, a, b, toe_low | col, nowhere, most) + 1, side] = True
    airborne = ~out.any(axis=1)
    out[airborne] |= widest[airborne]
    return out


def contact_edges(points: F64, planted: NDArray[np.bool_], fps: float, leg: float,
                  thresholds: ContactThresholds) -> list[list[tuple[float, float]]]:
    """Per foot (left, right), each stillness contact's touch-down and lift-off, in frames
    (fractional: interpolated between frames; the lift-off is the first instant off the
    ground, ``n_frames`` where the contact lasts to the clip's end).

    ``points`` (n_frames, 4, 3): ankle l, r, toe l, r; ``planted`` (n_frames, 2): the stillness
    contacts. Touch-down (:func:`touch_down_time`): the heel point (:data:`HEEL_BEHIND_ANKLE`)
    comes down to within ``edge_height_m`` of the lowest it comes as the foot lands, or the toe
    joint does first (a landing on the ball): a heel-height rule like the heel-marker height
    methods of gait analysis, on the contact's own ground, so a step or a ramp is ground too.
    Lift-off (:func:`lift_off_time`): the toe joint, or the heel point if it leaves later,
    moves horizontally faster than ``edge_swing_share`` of its own swing speed
    (:func:`stride_peak`): relative to the clip's own motion, like Ghoussayni et al.'s 2004
    (Gait Posture 20:266) threshold on the toe's speed, so a sprint and a shuffle leave at the
    same phase. Each edge moves by at most ``edge_max_s``, not into the next or previous
    contact and not past the contact's other end; a contact the clip cuts (at its first or last
    frame) keeps that edge: its touch-down or lift-off is not in the clip. Stillness alone
    starts late at a brisk walk, while the heel rolls in, and early at a slow one, while the
    ankle settles."""
    th = thresholds
    n = len(points)
    ankle, toe = points[:, :2], points[:, 2:]
    foot = np.stack([ankle - HEEL_BEHIND_ANKLE * (toe - ankle), toe], axis=2)  # (F, 2, 2, 3)
    # Zero-phase smoothing over a few hundredths of a second, whatever the rate: a marker's
    # jitter or a one-frame step (a toe marker jumping 8 mm) is no landing or leaving.
    z = box_filter(foot[..., 2], _width(th.edge_filter_s, fps))  # (F, 2 sides, heel / toe)
    moving = horizontal_speed(foot, fps, th.edge_filter_s)
    leaving = th.edge_swing_share * stride_peak(moving, fps)
    within = th.edge_height_m * leg / REFERENCE_LEG_M
    most = round(th.edge_max_s * fps)
    out: list[list[tuple[float, float]]] = []
    for side in range(planted.shape[1]):
        runs = true_runs(planted[:, side])
        mine = []
        for k, (a, b) in enumerate(runs):
            before = runs[k - 1][1] + 1 if k > 0 else 0
            after = runs[k + 1][0] - 1 if k + 1 < len(runs) else n - 1
            start, stop = float(a), float(n)
            if a > 0:
                landing = slice(max(before, a - most), min(b, a + most) + 1)
                start = landing.start + min(touch_down_time(z[landing, side, p], within)
                                            for p in range(2))
            if b < n - 1:
                leave = slice(max(a, b - most), min(after, b + most) + 1)
                stop = leave.start + max(lift_off_time(moving[leave, side, p],
                                                       leaving[leave, side, p])
                                         for p in range(2))
            # Never past the contact's other end: its frames were still and low, and at least
            # one of them stays on the ground (a foot leaving at once from a clip's first frame).
            mine.append((min(start, float(b)), max(stop, a + 1.0)))
        out.append(mine)
    return out


def touch_down_time(height: F64, within_m: float) -> float:
    """When a point lands, in frames from the first of ``height`` (m, a landing's frames):
    the last time before its lowest that it comes down to within ``within_m`` of that lowest,
    interpolated between frames; 0 where it is that low from the first frame on."""
    lowest = int(np.argmin(height))
    level = height[lowest] + within_m
    higher = np.flatnonzero(height[:lowest] > level)
    if len(higher) == 0:
        return 0.0
    k = int(higher[-1]) + 1  # the first frame of the last stretch within reach of the lowest
    return k - 1 + float((height[k - 1] - level) / (height[k - 1] - height[k]))


def lift_off_time(speed_mps: F64, limit_mps: F64) -> float:
    """When a point leaves, in frames from the first of ``speed_mps`` (a contact's last frames
    and those after it): the first time its speed rises over ``limit_mps``, interpolated
    between frames; the last frame where it never does, 0 where it is over it from the first."""
    over = np.flatnonzero(speed_mps > limit_mps)
    if len(over) == 0:
        return float(len(speed_mps) - 1)
    k = int(over[0])
    if k == 0:
        return 0.0
    below = limit_mps[k - 1] - speed_mps[k - 1]
    return k - 1 + float(below / (below + speed_mps[k] - limit_mps[k]))


def _edge_back(col: NDArray[np.bool_], a: int, b: int, down: NDArray[np.bool_],
               moving: NDArray[np.bool_], most: int) -> int:
    """Where the run ``a..b`` of ``col`` starts: back from ``a`` over the frames where
    ``down`` holds without a break (not into another run), or, when ``down`` fails at ``a``,
    on over the frames where ``moving`` holds; at most ``most`` frames, never past ``b``."""
    k = a
    if down[a]:
        while k > 0 and a - k < most and down[k - 1] and not col[k - 1]:
            k -= 1
    else:
        while k < b and k - a < most and moving[k]:
            k += 1
    return k


def _edge_on(col: NDArray[np.bool_], a: int, b: int, down: NDArray[np.bool_],
             moving: NDArray[np.bool_], most: int) -> int:
    """Where the run ``a..b`` of ``col`` ends: :func:`_edge_back` mirrored in time."""
    n = len(col)
    m = b
    if down[b]:
        while m < n - 1 and m - b < most and down[m + 1] and not col[m + 1]:
            m += 1
    else:
        while m > a and b - m < most and moving[m]:
            m -= 1
    return m


def detect_contacts(positions: F64, fps: float,
                    thresholds: ContactThresholds = ContactThresholds()) -> NDArray[np.bool_]:
    """Per-frame whole-foot contact flags for the left and right foot (see
    :func:`detect_foot_contacts`). ``positions`` (n_frames, N_JOINTS, 3). -> bool (n_frames, 2)."""
    return detect_foot_contacts(positions, fps, thresholds).foot


def contact_constraints(contact: NDArray[np.bool_], fps: float,
                        thresholds: ContactThresholds = ContactThresholds()) -> list[ConstraintSpec]:
    """Foot-contact constraints, one per contact interval, weight 1 on every contact frame.

    Each eases in and out over ``ease_s``, shortened where two contacts of one foot lie closer
    than two ramps: each ramp takes at most half the gap, so one foot's activations, ramps
    included, never overlap (the next starts no sooner than the previous stops)."""
    out: list[ConstraintSpec] = []
    duration = (contact.shape[0] - 1) / fps
    for side_i, side in enumerate("lr"):
        runs = true_runs(contact[:, side_i])
        for k, (a, b) in enumerate(runs):
            t0, t1 = a / fps, b / fps
            before = t0 - runs[k - 1][1] / fps if k > 0 else t0
            after = runs[k + 1][0] / fps - t1 if k + 1 < len(runs) else duration - t1
            ease_in = min(thresholds.ease_s, before if k == 0 else 0.5 * before)
            ease_out = min(thresholds.ease_s, after if k + 1 == len(runs) else 0.5 * after)
            out.append(ConstraintSpec(
                name=f"contact_{side}_{k}", kind="foot_contact", segment=f"ankle_{side}",
                activation=Activation(t0 - ease_in, t1 + ease_out, ease_in, ease_out),
                chain=(f"leg_{side}", "root"), priority=100, fraction=0.0,
            ))
    return out


def rigid_legs(positions: F64, pelvis2world: F64, tolerance_m: float = RIGID_LEG_M
               ) -> NDArray[np.bool_]:
    """Which legs (left, right) never move in the pelvis's frame: knee, ankle and toe within
    ``tolerance_m`` of one place relative to the pelvis over the whole clip, as a leg the
    source filled in a neutral pose holds them. -> bool (2,). A captured leg, even standing,
    moves by more (sway, breathing). ``positions`` (n_frames, N_JOINTS, 3),
    ``pelvis2world`` (n_frames, 3, 3)."""
    out = np.zeros(2, dtype=bool)
    if len(positions) < 2:
        return out
    pelvis = positions[:, J["pelvis"]]
    for i, s in enumerate("lr"):
        joints = positions[:, [J[f"knee_{s}"], J[f"ankle_{s}"], J[f"toe_{s}"]]] - pelvis[:, None]
        local = np.einsum("fji,fkj->fki", pelvis2world, joints)  # world -> pelvis frame
        spread = np.linalg.norm(local - np.median(local, axis=0), axis=-1).max()
        out[i] = bool(spread < tolerance_m)
    return out


# --- gait events (C3D ``EVENT`` group) ---------------------------------------------------------

#: How labs spell a gait event, after lower-casing and dropping all but letters: Vicon Nexus
#: ("Foot Strike", "Foot Off", context "Left"/"Right"), Motion Analysis Cortex (context "LHS",
#: "RTO"), and the clinical names (heel strike, initial contact, toe off).
EVENT_KINDS = {
    "strike": ("footstrike", "heelstrike", "initialcontact", "footcontact", "hs", "fs", "ic"),
    "off": ("footoff", "toeoff", "footlift", "to", "fo"),
}


def gait_event_kind(label: str, context: str) -> tuple[str, str] | None:
    """(side ``"l"``/``"r"``, kind ``"strike"``/``"off"``) of a C3D event, or None for other
    events (a force-plate mark, a "General" context).

    The side is the context ("Left", "Right") or the first letter of an abbreviation that names
    both ("LHS", "RTO"); the kind is the label, or the abbreviation's rest. Numbers in a label
    ("Foot Strike1") are ignored."""
    words = [re.sub(r"[^a-z]", "", w) for w in (label.lower(), context.lower())]
    label_w, context_w = words
    side = {"left": "l", "right": "r"}.get(context_w)
    kind_text = label_w
    for text in (context_w, label_w):
        if side is None and len(text) > 1 and text[0] in "lr" and _kind(text[1:]):
            side, kind_text = text[0], text[1:]
    if side is None:
        for text in (label_w, context_w):
            for name, code in (("left", "l"), ("right", "r")):
                if text.startswith(name) and _kind(text[len(name):]):
                    side, kind_text = code, text[len(name):]
    kind = _kind(kind_text) or (_kind(context_w) if side else None)
    return (side, kind) if side and kind else None


def _kind(text: str) -> str | None:
    for kind, names in EVENT_KINDS.items():
        if text in names:
            return kind
    return None


#: Event times are written rounded (to the microsecond, or a float's precision): an event this
#: close after a frame's instant is at that frame.
EVENT_TIME_TOLERANCE_S = 1e-6


def contacts_from_events(events: list[dict[str, Any]], n_frames: int, fps: float
                         ) -> NDArray[np.bool_]:
    """Per-frame contact flags (n_frames, 2) from gait events (``{"side", "kind", "time_s"}``,
    times in the motion's seconds): a foot is down from each strike to the next foot off, on
    the frames whose instant lies from the strike up to the foot off (as detected contacts,
    :func:`touch_down_to_lift_off`; a microsecond's tolerance for times written rounded).
    Before its first event a foot is in the state that event ends (down before a foot off), after
    its last in the state that event begins."""
    t = np.arange(n_frames) / fps + EVENT_TIME_TOLERANCE_S
    out = np.zeros((n_frames, 2), dtype=bool)
    for side_i, side in enumerate("lr"):
        mine = sorted((e["time_s"], e["kind"]) for e in events if e.get("side") == side
                      and e.get("kind") in ("strike", "off"))
        if not mine:
            continue
        state = np.full(n_frames, mine[0][1] == "off")
        for time_s, kind in mine:
            state[t >= time_s] = kind == "strike"
        out[:, side_i] = state
    return out


# --- in-place (treadmill) stance ---------------------------------------------------------------

#: A clip is in place when its root travels horizontally (over a second) at a median below
#: this many legs/s ...
IN_PLACE_ROOT_PER_LEG = 0.15
#: ... while the lower foot moves at a median of at least this many legs/s, and most of that
#: motion (this share of its speed) goes one way: a belt carrying the stance foot backwards.
BELT_MIN_PER_LEG = 0.4
BELT_STEADINESS = 0.6
#: A belt must be one a treadmill runs at for the gait seen (issue 31, class 2): the fastest a
#: body of leg ``L`` goes is ``sqrt(froude * g * L)``. A walk (a foot always low: no flight
#: phase) tops out at a Froude number of 1 (the inverted pendulum leaves the ground: 2.8 m/s for
#: a 0.8 m leg); a run at a sprint's, 6.25 (7 m/s for a 0.8 m leg).
BELT_MAX_FROUDE_WALK = 1.0
BELT_MAX_FROUDE_RUN = 6.25
GRAVITY_MPS2 = 9.81
#: The gait is a run when neither foot is low on at least this share of the frames.
FLIGHT_SHARE_RUN = 0.1
#: The belt carries the stance feet backwards: its direction within 45 degrees of the body's
#: backward (the hips' forward, turned round) on average over the belt's samples ...
BELT_BACKWARD_COS = 0.7
#: ... and steadily while planted: each stance (a foot the lower and low for at least
#: ``BELT_MIN_STANCE_S``) moves on net at the belt's velocity (within a quarter of its speed, or
#: a tenth of a leg per second), over at least this share of the stance time and on both feet.
BELT_MIN_STANCE_S = 0.08
BELT_STANCE_SHARE = 0.5


def max_belt_speed(leg_m: float, running: bool) -> float:
    """The fastest plausible belt (m/s) for a body of thigh + shank ``leg_m`` (m), walking or
    running (:data:`BELT_MAX_FROUDE_WALK`, :data:`BELT_MAX_FROUDE_RUN`)."""
    froude = BELT_MAX_FROUDE_RUN if running else BELT_MAX_FROUDE_WALK
    return float(np.sqrt(froude * GRAVITY_MPS2 * leg_m))


def treadmill_belt(positions: F64, fps: float) -> F64 | None:
    """The belt's horizontal velocity (2,) m/s of a treadmill-like, in-place clip, or None.

    In place: the pelvis hardly moves while the stance foot (the lower ankle, on frames where
    it is within a few centimetres of its lowest) slides steadily one way at walking or running
    speed, as it does on a treadmill or in an in-place walk cycle. The belt velocity is the
    velocity most of that foot's samples share. It must be physically plausible, else there is
    no belt (None): no faster than the gait seen goes (:func:`max_belt_speed`), carrying the
    stance feet backwards, and each foot's stances moving at it while planted (the constants
    above). ``positions`` (n_frames, N_JOINTS, 3) metres, Z up."""
    if len(positions) < max(3, int(fps)):
        return None
    leg = leg_of(positions)
    # The root's travel over one second (its sway within a stride does not count).
    root = positions[:, J["pelvis"], :2]
    w = min(len(root) - 1, max(1, round(fps)))
    travel = np.linalg.norm(root[w:] - root[:-w], axis=-1) * fps / w
    if np.median(travel) > IN_PLACE_ROOT_PER_LEG * leg:
        return None
    ankles = positions[:, [J["ankle_l"], J["ankle_r"]]]
    lower = np.argmin(ankles[..., 2], axis=1)
    frames = np.arange(len(ankles))
    stance = ankles[frames, lower]  # (F, 3)
    velocity = box_filter(np.gradient(ankles[..., :2], axis=0) * fps, _width(0.03, fps))
    v = velocity[frames, lower]
    ground = np.percentile(stance[:, 2], 5)
    low = stance[:, 2] < ground + 0.06 * leg  # 5 cm for a 0.8 m leg
    if low.sum() < 3:
        return None
    samples = v[low]
    speed_median = float(np.median(np.linalg.norm(samples, axis=-1)))
    # The belt carries the stance foot at one velocity: the one most stance samples share
    # (within a tenth of a leg per second), then their mean; heel-strike and push-off frames,
    # where the foot rolls, fall outside it.
    tolerance = 0.1 * leg
    candidates = samples[:: max(1, len(samples) // 400)]
    near = np.linalg.norm(samples[None] - candidates[:, None], axis=-1) < tolerance
    best = candidates[int(np.argmax(near.sum(axis=1)))]
    belt = samples[np.linalg.norm(samples - best, axis=-1) < tolerance].mean(axis=0)
    speed = float(np.linalg.norm(belt))
    if speed_median < BELT_MIN_PER_LEG * leg or speed < BELT_STEADINESS * speed_median:
        return None
    # Plausible for the gait seen: a run has frames with neither foot low (flight).
    running = float(np.mean(~np.any(ankles[..., 2] < ground + 0.06 * leg, axis=1))) >= FLIGHT_SHARE_RUN
    if speed > max_belt_speed(leg, running):
        return None
    # Backwards: against the way the hips face (forward = left x up), on the belt's samples.
    left = positions[:, J["hip_l"], :2] - positions[:, J["hip_r"], :2]
    forward = np.stack([left[:, 1], -left[:, 0]], axis=-1)
    forward /= np.maximum(np.linalg.norm(forward, axis=-1, keepdims=True), 1e-12)
    if float(np.mean(forward[low] @ (belt / speed))) > -BELT_BACKWARD_COS:
        return None
    # Steadily while planted: each stance's net velocity is the belt's, on both feet.
    agree = np.zeros(2)
    total = 0.0
    for side in (0, 1):
        for a, b in true_runs(low & (lower == side)):
            duration = (b - a) / fps
            if duration < BELT_MIN_STANCE_S:
                continue
            total += duration
            net = (ankles[b, side, :2] - ankles[a, side, :2]) / duration
            if np.linalg.norm(net - belt) < max(tolerance, 0.25 * speed):
                agree[side] += duration
    if not (np.all(agree > 0) and agree.sum() >= BELT_STANCE_SHARE * total):
        return None
    out: F64 = belt
    return out
