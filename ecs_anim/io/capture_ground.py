"""The ground a capture stood on (issue 31, item 2), estimated at import from its planted soles.

A capture made on a ramp, a step or uneven terrain carries that ground in its root's height: the
pelvis rises with each step up. Played on another ground as it is, the character would climb
steps that are not there (its free feet lifted, its pelvis held up by the terrain it left
behind). Each foot contact stood on one level: the height of the sole point it planted (the
heel under the ankle, the ball under the toe joint). The ground under the body follows the
levels of the feet supporting it, smoothly, as GroundAdapt follows the character's own ground;
the motion is stored relative to it (every joint of a frame moved down by it), and GroundAdapt
puts it back from whatever ground the character has.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.ground_adapt import BALL_HEIGHT_PER_LEG, GROUND_SMOOTHING_S
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.contacts import box_filter, frames_of, true_runs

F64 = NDArray[np.float64]
B1 = NDArray[np.bool_]

#: Successive contacts stand at most this many leg lengths apart in height (a high step, 0.3 m
#: for a 0.86 m leg) ...
MAX_GROUND_STEP_PER_LEG = 0.35
#: ... and, beyond a capture's noise (this many leg lengths: two feet planted at once can sit a
#: few centimetres apart), their levels change at most this many leg lengths per second between
#: their middles (a brisk stair climb: 0.4 m/s; the pelvis would otherwise jump with a stray
#: contact).
GROUND_NOISE_PER_LEG = 0.05
MAX_GROUND_SPEED_PER_LEG = 1.0
#: A capture in which more than this share of the contacts lie off any walkable ground does not
#: show its ground (a video estimate drifting in depth, feet on pedals).
MAX_OFF_GROUND_SHARE = 1 / 3


def contact_levels(positions: F64, foot: B1, heel: B1, ball: B1, ankle_height: F64,
                   leg_m: float) -> list[tuple[float, float, int, int, int]]:
    """(middle frame, ground height m, side, first frame, last frame) of every foot contact,
    in time order: its height is the median, over the contact, of the sole under the point it
    planted (the heel under the ankle where the heel is planted, the ball under the toe joint
    where only the ball is; the lower of the two where the contact plants neither).
    ``positions`` (n_frames, N_JOINTS, 3) m, Z up; ``foot``, ``heel``, ``ball`` bool
    (n_frames, 2); ``ankle_height`` (2,) m; ``leg_m`` thigh + shank."""
    ball_height = BALL_HEIGHT_PER_LEG * leg_m
    levels: list[tuple[float, float, int, int, int]] = []
    for side, s in enumerate("lr"):
        heel_sole = positions[:, J[f"ankle_{s}"], 2] - ankle_height[side]
        ball_sole = positions[:, J[f"toe_{s}"], 2] - ball_height
        sole = np.where(heel[:, side], heel_sole, np.where(ball[:, side], ball_sole,
                                                           np.minimum(heel_sole, ball_sole)))
        for a, b in true_runs(foot[:, side]):
            levels.append((0.5 * (a + b), float(np.median(sole[a:b + 1])), side, a, b))
    return sorted(levels)


def _plausible(frames: F64, heights: F64, fps: float, leg_m: float) -> NDArray[np.bool_]:
    """Which of two successive contact levels (middle frames ``frames``, heights m) a walkable
    ground joins: no higher step than :data:`MAX_GROUND_STEP_PER_LEG`, no faster change than
    :data:`MAX_GROUND_SPEED_PER_LEG` beyond :data:`GROUND_NOISE_PER_LEG`. -> bool (len - 1,)."""
    rise = np.abs(np.diff(heights))
    seconds = np.diff(frames) / fps
    ok: NDArray[np.bool_] = (rise <= MAX_GROUND_STEP_PER_LEG * leg_m) & (
        rise <= leg_m * np.maximum(GROUND_NOISE_PER_LEG, MAX_GROUND_SPEED_PER_LEG * seconds))
    return ok


def capture_ground(positions: F64, fps: float, foot: B1, heel: B1, ball: B1, ankle_height: F64,
                   leg_m: float) -> tuple[F64, str]:
    """The capture's ground height under the body at each frame (n_frames,) m, and how it was
    found.

    Each contact stood on one level (:func:`contact_levels`). Where two successive levels no
    walkable ground joins (:func:`_plausible`), the higher is left out (a foot held still in the
    air, a stray detection: contacts lie above the ground, never under it), the worst pair
    first; if that leaves out more than :data:`MAX_OFF_GROUND_SHARE` of them, the capture does
    not show its ground: it is taken as level at the contacts' median height (``"level: ..."``).
    Otherwise the ground under the body is the lowest level of the feet supporting it (a foot
    put onto a step does not lift the body until the other leaves the lower level), carried
    linearly over frames no foot supports, smoothed without lag over about twice GroundAdapt's
    time constant (:data:`~ecs_anim.core.ground_adapt.GROUND_SMOOTHING_S`) (``"contacts"``). A clip with no contact: zero
    (``"none"``). ``fps`` the clip's rate; other arguments as for :func:`contact_levels`."""
    levels = contact_levels(positions, foot, heel, ball, ankle_height, leg_m)
    n = len(positions)
    if not levels:
        return np.zeros(n), "none"
    frames, heights = (np.array([v[k] for v in levels]) for k in (0, 1))
    kept = np.arange(len(levels))
    while len(kept) > 1:
        ok = _plausible(frames[kept], heights[kept], fps, leg_m)
        if ok.all():
            break
        bad = np.flatnonzero(~ok)
        pair = int(bad[np.argmax(np.abs(np.diff(heights[kept]))[bad])])
        kept = np.delete(kept, pair + int(heights[kept[pair + 1]] > heights[kept[pair]]))
    dropped = len(levels) - len(kept)
    if dropped > MAX_OFF_GROUND_SHARE * len(levels):
        return (np.full(n, float(np.median(heights))),
                f"level: {dropped} of {len(levels)} contacts off any walkable ground")
    lowest = np.full(n, np.inf)
    for k in kept:
        _, height, _, a, b = levels[k]
        lowest[a:b + 1] = np.minimum(lowest[a:b + 1], height)
    supported = np.flatnonzero(np.isfinite(lowest))
    under = np.interp(np.arange(n), supported, lowest[supported])
    # Centred (no lag: the pelvis goes down a step while the foot is still on the upper one),
    # a triangle over twice GroundAdapt's time constant either side.
    width = frames_of(2.0 * GROUND_SMOOTHING_S, fps) | 1
    ground: F64 = box_filter(box_filter(under, width), width)
    return ground, "contacts" if not dropped else f"contacts ({dropped} off the ground left out)"


__all__ = ["GROUND_NOISE_PER_LEG", "MAX_GROUND_SPEED_PER_LEG", "MAX_GROUND_STEP_PER_LEG",
           "MAX_OFF_GROUND_SHARE", "capture_ground", "contact_levels"]
