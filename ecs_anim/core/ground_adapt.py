"""Ground adaptation of a scaled pose (paper §7), as a pure batched kernel.

Given where each ankle must go (its footprint on the ground, weighted by the contact's
activation), the pelvis is lowered to ``min(h_original, h_reach_left, h_reach_right)`` and each
leg's half-plane frame is turned (smallest rotation, so the knee keeps its side) and its length
fraction reset so the ankle lands on its target. Nothing here keeps state: locking footprints for
the duration of a contact is the GroundAdapt system's job.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.ground import Ground
from ecs_anim.core.morphology import leg_length
from ecs_anim.core.normalized import (
    SIDE_JOINTS,
    SIDE_LENGTHS,
    DecodedLegs,
    DecodedPose,
    NormalizedPoses,
    decode_legs,
)
from ecs_anim.core.rotations import quat_from_matrix, rotation_between

F64 = NDArray[np.float64]

#: Height of the ball-of-foot joint above the sole, as a fraction of the leg (thigh + shank):
#: the toe joint must stay this high above the ground (also used by the metrics).
BALL_HEIGHT_PER_LEG = 0.025 / 0.86

#: Legs are never stretched beyond this fraction of thigh + shank: a fully straight knee has an
#: undefined bend direction and looks locked.
MAX_LEG_EXTENSION = 0.995

#: Time constant (s) with which the motion's floor follows the ground under the supporting feet
#: (GroundAdapt); import smooths the ground a capture stood on over twice it, centred.
GROUND_SMOOTHING_S = 0.15

#: A planted leg out of reach lowers the pelvis only until it leans this far from the vertical
#: (sine of 60 degrees); beyond that, and where the pelvis cannot come lower (a body lying on the
#: ground), the root moves horizontally towards the footprint instead (paper §9: the root follows
#: what the limbs cannot reach), so the foot stays where it was planted ...
MAX_LOWERING_LEAN_SIN = 0.8660254037844386
#: ... by at most this share of the leg's reach: a footprint further away is no foot left where
#: it stood but a glitch, and the leg stretches towards it rather than the body jumping.
MAX_ROOT_FOLLOW_PER_REACH = 0.25

#: The tallest rise a body steps up, as a share of its leg (thigh + shank): a knee-high step.
#: GroundAdapt stops a character walking into a taller one; ``run`` says so before the first
#: tick (:func:`ecs_anim.runtime.feasibility.ground_lines`).
STEP_UP_PER_LEG = 0.5

#: A heel this far under the ground (m) is lifted: well below the metrics' 1 mm, above rounding.
HEEL_TOLERANCE_M = 1e-6
#: A toe (or ankle) end this far under its clearance (m) is pitched no further (:func:`pitched`):
#: under what the metrics show (0.0001 mm); 1e-6 m showed as 0.001 mm of penetration in the
#: scenarios' reports, and this costs 0.1 ground queries a character more.
TOE_TOLERANCE_M = 1e-9
#: :func:`pitched` takes the secant slope only within these multiples of a flat ground's.
MIN_SECANT_RATIO, MAX_SECANT_RATIO = 0.5, 2.0

#: Which part of a foot the motion plants, per frame, as a *sole roll*: 0 the heel (the toe
#: free: heel strike), 1 the ball (the heel free: heel off), 0.5 both (flat, or not known).
#: Sampled between frames, a roll under HEEL_ROLL plants the heel, over BALL_ROLL the ball.
HEEL_ROLL, BALL_ROLL = 0.25, 0.75

#: A foot moves its footprint onto the other sole point (heel to ball at heel off) only once
#: that point is this close to the ground, per leg length (0.4 mm for a 0.86 m leg, under the
#: metrics' 1 mm of sliding): it turns about the point it stands on and never jumps.
SWITCH_PER_LEG = 0.0005


def sole_roll(heel: NDArray[np.bool_], ball: NDArray[np.bool_]) -> F64:
    """The sole roll (:data:`HEEL_ROLL`) of planted heel / ball flags (any shape): 0 where only
    the heel is planted, 1 where only the ball is, 0.5 elsewhere."""
    roll: F64 = np.where(heel & ~ball, 0.0, np.where(ball & ~heel, 1.0, 0.5))
    return roll


def pivot_wanted(roll: F64, current: NDArray[np.int64]) -> NDArray[np.int64]:
    """The sole point (0 heel, 1 ball) a roll plants, else ``current`` (same shapes)."""
    wanted: NDArray[np.int64] = np.where(roll < HEEL_ROLL, 0, np.where(roll > BALL_ROLL, 1, current))
    return wanted


def pitch_slope(dz: F64, deficit: F64, last_dz: F64, last_deficit: F64, rise: F64) -> F64:
    """How a foot's deficit (how far its other end is under where it should be, m) changes per
    unit of its direction's z, for :func:`pitched`'s next step: the secant through this pass's
    (``dz``, ``deficit``) and the last one's, where that is within :data:`MIN_SECANT_RATIO` ..
    :data:`MAX_SECANT_RATIO` of a flat ground's ``-rise`` (``sign * foot``: how far the end
    rises per unit of z, m), else ``-rise`` (the first pass, a pass that did not move, an edge
    of stairs or a height grid's cell). All arrays (...)."""
    flat = -rise
    step = dz - last_dz
    moved = step != 0.0
    secant = (deficit - last_deficit) / np.where(moved, step, 1.0)
    ratio = secant / flat
    slope: F64 = np.where(moved & (ratio > MIN_SECANT_RATIO) & (ratio < MAX_SECANT_RATIO),
                          secant, flat)
    return slope


def pitched(ground: Ground, origin: F64, d: F64, foot: F64, sign: float, clearance: F64,
            passes: int) -> F64:
    """Foot directions ``d`` (..., 3) unit, world, turned in their vertical planes, at most
    ``passes`` times asking the ground again, until each foot's other end
    ``origin + sign * foot * d`` is ``clearance`` (...) metres above the ground or less than
    :data:`TOE_TOLERANCE_M` under that; ``sign`` +1 about the ankle (the toe end lifted), -1
    about the ball (the ankle end). ``origin`` (..., 3), ``foot`` (...) metres.

    Each pass is a secant step on the direction's z (:func:`pitch_slope`): the first one
    assumes a flat ground under the end (exact on a plane), the next ones also how the ground
    under the end changed as it moved, so a pass or two suffice on a slope or bumps."""
    flat = np.maximum(np.linalg.norm(d[..., :2], axis=-1), 1e-9)
    heading = d[..., :2] / flat[..., None]
    dz = d[..., 2]
    end = origin + sign * foot[..., None] * d
    deficit = ground.height(end[..., :2]) + clearance - end[..., 2]
    last_dz, last_deficit = dz, deficit
    for _ in range(passes):
        short = deficit > TOE_TOLERANCE_M
        if not np.any(short):
            break
        slope = pitch_slope(dz, deficit, last_dz, last_deficit, sign * foot)
        last_dz, last_deficit = dz, deficit
        dz = np.where(short, np.clip(dz - deficit / slope, -1.0, 1.0), dz)
        turned = np.concatenate([heading * np.sqrt(1.0 - dz**2)[..., None], dz[..., None]], -1)
        d = np.where(short[..., None], turned, d)
        end = origin + sign * foot[..., None] * d
        deficit = ground.height(end[..., :2]) + clearance - end[..., 2]
    return d


def planted_foot(ground: Ground, pivot: NDArray[np.int64], sole_point: F64, d: F64, foot: F64,
                 ankle_height: F64, ball: F64, passes: int) -> tuple[F64, F64]:
    """(ankle (..., 3), foot direction (..., 3)) of feet standing on ``sole_point`` (..., 3)
    (world, on the ground) with the heel (``pivot`` 0) or the ball (1), pitched as the motion's
    ``d`` unless that puts the foot's other end under the ground (:func:`pitched`).
    ``foot``, ``ankle_height``, ``ball`` (...) metres: the ankle-to-toe length and the ankle's
    and the toe joint's heights above the sole."""
    on_heel = (pivot == 0)[..., None]
    ankle = sole_point + np.stack([0 * ball, 0 * ball, ankle_height], -1)
    toe = sole_point + np.stack([0 * ball, 0 * ball, ball], -1)
    d_heel = pitched(ground, ankle, d, foot, 1.0, ball, passes)
    d_ball = pitched(ground, toe, d, foot, -1.0, ankle_height, passes)
    d_out = np.where(on_heel, d_heel, d_ball)
    return np.where(on_heel, ankle, toe - foot[..., None] * d_ball), d_out


def heel_depth(ground: Ground, ankles: F64, ankle_height: F64) -> F64:
    """How far each heel (the sole under the ankle) is below the ground, metres: ``ankles``
    (..., 3) world, ``ankle_height`` (...) the ankle's height above the sole; negative above."""
    return ground.height(ankles[..., :2]) + ankle_height - ankles[..., 2]


def vertical_slack_for_reach(hips: F64, ankle_targets: F64, reach: F64) -> F64:
    """How far each hip may move vertically and still reach its ankle target.

    ``hips`` (n, 2, 3) and ``ankle_targets`` (n, 2, 3) in metres, ``reach`` (n, 2) the longest
    allowed hip-ankle distance. Returns (n, 2) metres: negative where the hip must come down by
    that much; a target horizontally out of reach asks for the hip straight above it at ``0``
    vertical distance (the leg then stretches towards it). The pelvis moves vertically with the
    hips, so this is also how much the pelvis may move (paper §7's ``h2``, ``h3`` minus ``h1``).
    """
    horizontal = np.linalg.norm(hips[..., :2] - ankle_targets[..., :2], axis=-1)
    vertical = np.sqrt(np.maximum(reach**2 - horizontal**2, 0.0))
    lift: F64 = ankle_targets[..., 2] + vertical - hips[..., 2]
    return lift


def horizontal_reach_excess(hips: F64, ankle_targets: F64, reach: F64) -> F64:
    """How far each hip must move horizontally towards its ankle target for the leg to reach
    it once the pelvis has come down, leaning at most :data:`MAX_LOWERING_LEAN_SIN` (or
    further where the hip already is that low).

    ``hips`` (n, 2, 3) and ``ankle_targets`` (n, 2, 3) in metres, ``reach`` (n, 2) the longest
    allowed hip-ankle distance. Returns (n, 2, 3) metres, horizontal, at most
    :data:`MAX_ROOT_FOLLOW_PER_REACH` of the reach: zero for a leg that can reach by lowering
    the pelvis.
    """
    towards = ankle_targets[..., :2] - hips[..., :2]
    horizontal = np.linalg.norm(towards, axis=-1)
    vertical = hips[..., 2] - ankle_targets[..., 2]
    at_this_height = np.sqrt(np.maximum(reach**2 - vertical**2, 0.0))
    allowed = np.maximum(MAX_LOWERING_LEAN_SIN * reach, at_this_height)
    excess = np.clip(horizontal - allowed, 0.0, MAX_ROOT_FOLLOW_PER_REACH * reach) \
        / np.maximum(horizontal, 1e-12)
    out = np.zeros_like(hips)
    out[..., :2] = excess[..., None] * towards
    return out


def adapt_to_ground(poses: NormalizedPoses, lengths: F64, ankle_targets: F64,
                    weights: F64, root_height: F64,
                    decoded: DecodedPose | DecodedLegs | None = None) -> NormalizedPoses:
    """Put the ankles on their targets, lowering the pelvis only as much as the legs in contact
    need (paper §7: ``h = min(h1, h2, h3)``).

    Parameters
    ----------
    poses : (n,) normalized poses (already sampled and placed for this tick).
    lengths : (n, N_LENGTHS) each character's segment lengths.
    ankle_targets : (n, 2, 3) where each ankle should go (world, metres): a footprint for a foot
        in contact, wherever the caller wants a free foot (e.g. lifted clear of the ground).
    weights : (n, 2) contact activation in [0, 1]: how much each leg's reach may lower the pelvis.
    root_height : (n,) the pelvis height the motion wants here (``h1``), metres.
    decoded : ``decode(poses, lengths)`` if the caller has it already.

    Returns new poses (root position, leg frames and fractions changed; all else shared). A
    target still out of reach leaves the leg stretched (to :data:`MAX_LEG_EXTENSION`) towards it.
    """
    decoded = decode_legs(poses, lengths, lengths) if decoded is None else decoded
    if isinstance(decoded, DecodedLegs):
        hips, pelvis_now_z = decoded.hips, decoded.pelvis[:, 2]
    else:
        hips, pelvis_now_z = decoded.positions[:, list(SIDE_JOINTS["hip"])], decoded.positions[:, 0, 2]
    w = np.clip(weights, 0.0, 1.0)
    thigh, shank = lengths[:, SIDE_LENGTHS["thigh"]], lengths[:, SIDE_LENGTHS["shank"]]
    reach = MAX_LEG_EXTENSION * (thigh + shank)
    # Put the pelvis at h1 first; a leg horizontally out of reach moves it towards its target,
    # then a leg lowers it, each in proportion to its contact weight.
    up = np.zeros_like(hips[:, 0])
    up[:, 2] = root_height - pelvis_now_z
    up += np.sum(w[..., None] * horizontal_reach_excess(hips + up[:, None], ankle_targets, reach),
                 axis=1)
    needed = vertical_slack_for_reach(hips + up[:, None], ankle_targets, reach)
    pelvis_z = root_height + np.min(w * np.minimum(needed, 0.0), axis=1)
    shift = up.copy()
    shift[:, 2] = pelvis_z - pelvis_now_z
    new_hips = hips + shift[:, None]
    # Re-aim each leg: turn its half-plane frame so z points at the target, set the fraction.
    to_target = ankle_targets - new_hips
    turn = rotation_between(decoded.leg2world[..., :, 2], to_target)
    new_leg2pelvis = np.swapaxes(decoded.pelvis2world, -1, -2)[:, None] @ (turn @ decoded.leg2world)
    distance = np.minimum(np.linalg.norm(to_target, axis=-1), reach)
    root_position = poses.root_position.copy()
    root_position[:, :2] += shift[:, :2] / leg_length(lengths)[:, None]
    root_position[:, 2] = pelvis_z / leg_length(lengths)
    return replace(poses, root_position=root_position,
                   leg_frame=quat_from_matrix(new_leg2pelvis),
                   leg_fraction=distance / (thigh + shank))


def adapt_keeping_heels_up(poses: NormalizedPoses, lengths: F64, ankle_targets: F64, weights: F64,
                           root_height: F64, decoded: DecodedPose | DecodedLegs, ground: Ground,
                           passes: int = 4) -> tuple[NormalizedPoses, DecodedLegs]:
    """:func:`adapt_to_ground`, then lift each ankle target whose leg, stretched short of it,
    would put the heel under the ground; returns the poses and their decoded legs.

    A target out of the leg's reach (a contact ramping out while the pelvis rises, say) leaves
    the ankle on the line from the hip towards it: over a step edge that point can be above the
    higher step while the target is above the lower one (heels sank 12-31 mm on stairs).
    Raising the target turns that line up and back, so a few passes suffice. Arguments as for
    :func:`adapt_to_ground` (``decoded``: the pose the legs are re-aimed from).
    """
    ankle_height = lengths[:, SIDE_LENGTHS["ankle_height"]]
    adapted = adapt_to_ground(poses, lengths, ankle_targets, weights, root_height, decoded)
    legs = decode_legs(adapted, lengths, lengths)
    for _ in range(passes):
        deficit = heel_depth(ground, legs.ankles, ankle_height)
        if not np.any(deficit > HEEL_TOLERANCE_M):
            break
        ankle_targets = ankle_targets.copy()
        ankle_targets[..., 2] += np.maximum(deficit, 0.0)
        adapted = adapt_to_ground(poses, lengths, ankle_targets, weights, root_height, decoded)
        legs = decode_legs(adapted, lengths, lengths)
    return adapted, legs


__all__ = ["BALL_ROLL", "GROUND_SMOOTHING_S", "HEEL_ROLL", "MAX_LOWERING_LEAN_SIN",
           "MAX_ROOT_FOLLOW_PER_REACH", "MAX_SECANT_RATIO", "MIN_SECANT_RATIO", "STEP_UP_PER_LEG",
           "SWITCH_PER_LEG", "TOE_TOLERANCE_M", "adapt_keeping_heels_up", "adapt_to_ground",
           "heel_depth", "horizontal_reach_excess", "pitch_slope", "pitched", "pivot_wanted",
           "planted_foot", "sole_roll", "vertical_slack_for_reach"]
