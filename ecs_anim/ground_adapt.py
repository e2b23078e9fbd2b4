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

from .morphology import leg_length
from .normalized import SIDE_LENGTHS, NormalizedPoses, decode
from .rotations import quat_from_matrix, rotation_between

F64 = NDArray[np.float64]

#: Legs are never stretched beyond this fraction of thigh + shank: a fully straight knee has an
#: undefined bend direction and looks locked.
MAX_LEG_EXTENSION = 0.995


def pelvis_height_for_reach(hips: F64, pelvis_z: F64, ankle_targets: F64, reach: F64) -> F64:
    """Highest pelvis height at which a hip can still reach its ankle target.

    ``hips`` (n, 2, 3) hip positions for the current pelvis height ``pelvis_z`` (n,);
    ``ankle_targets`` (n, 2, 3); ``reach`` (n, 2) metres. Returns (n, 2): for each leg, the pelvis
    height putting the hip exactly ``reach`` above-and-beside its target (or straight above it
    when the target is horizontally out of reach).
    """
    horizontal = np.linalg.norm(hips[..., :2] - ankle_targets[..., :2], axis=-1)
    vertical = np.sqrt(np.maximum(reach**2 - horizontal**2, 0.0))
    hip_below_pelvis = pelvis_z[:, None] - hips[..., 2]
    return ankle_targets[..., 2] + vertical + hip_below_pelvis


def adapt_to_ground(poses: NormalizedPoses, lengths: F64, ankle_targets: F64,
                    weights: F64, root_height: F64) -> NormalizedPoses:
    """Put the ankles on their targets, lowering the pelvis only as much as needed.

    Parameters
    ----------
    poses : (n,) normalized poses (already sampled for this tick).
    lengths : (n, N_LENGTHS) each character's segment lengths.
    ankle_targets : (n, 2, 3) where each ankle should be (world, metres), e.g. its footprint.
    weights : (n, 2) contact activation in [0, 1]; 0 leaves a leg as the motion has it.
    root_height : (n,) the pelvis height the motion wants here (``h1`` of the paper), metres.

    Returns new poses (root height, leg frames and fractions changed; all else shared).
    """
    decoded = decode(poses, lengths)
    p = decoded.positions
    hips = p[:, [1, 5]]
    ankles = p[:, [3, 7]]
    w = np.clip(weights, 0.0, 1.0)[..., None]
    targets = ankles + w * (ankle_targets - ankles)
    # Move the pelvis to the wanted height first, then lower it where a leg cannot reach.
    dz = root_height - p[:, 0, 2]
    hips_at_h1 = hips + np.stack([np.zeros_like(dz), np.zeros_like(dz), dz], -1)[:, None, :]
    thigh, shank = lengths[:, SIDE_LENGTHS["thigh"]], lengths[:, SIDE_LENGTHS["shank"]]
    reach = MAX_LEG_EXTENSION * (thigh + shank)
    limits = pelvis_height_for_reach(hips_at_h1, root_height, targets, reach)
    pelvis_z = np.min(np.concatenate([root_height[:, None], limits], axis=1), axis=1)
    new_hips = hips_at_h1.copy()
    new_hips[..., 2] += (pelvis_z - root_height)[:, None]
    # Re-aim each leg: turn its half-plane frame so z points at the target, set the fraction.
    pelvis2world = decoded.pelvis2world
    old_leg2world = decoded.leg2world
    to_target = targets - new_hips
    turn = rotation_between(old_leg2world[..., :, 2], to_target)
    new_leg2world = turn @ old_leg2world
    new_leg2pelvis = np.swapaxes(pelvis2world, -1, -2)[:, None] @ new_leg2world
    distance = np.minimum(np.linalg.norm(to_target, axis=-1), reach)
    root_position = poses.root_position.copy()
    root_position[:, 2] = pelvis_z / leg_length(lengths)
    return replace(poses, root_position=root_position,
                   leg_frame=quat_from_matrix(new_leg2pelvis),
                   leg_fraction=distance / (thigh + shank))


__all__ = ["adapt_to_ground", "pelvis_height_for_reach"]
