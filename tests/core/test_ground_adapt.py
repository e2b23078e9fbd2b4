"""Paper §7 on stairs: ankles land on their footprints, the pelvis only drops as needed."""

import numpy as np
import pytest

from conftest import MOTIONS_DIR
from ecs_anim.core.ground import Bumps, Combined, Plane, Slope, Stairs
from ecs_anim.core.ground_adapt import (
    MAX_LEG_EXTENSION,
    MAX_ROOT_FOLLOW_PER_REACH,
    TOE_TOLERANCE_M,
    adapt_to_ground,
    pitched,
)
from ecs_anim.core.morphology import Morphology, bone_lengths_of
from ecs_anim.core.normalized import decode
from ecs_anim.core.skeleton import BONE_JOINTS
from ecs_anim.io.importing import import_bvh


def test_feet_land_on_stairs_and_pelvis_obeys_the_min_rule():
    walk = import_bvh(MOTIONS_DIR / "walk.bvh")
    morph = Morphology.preset("child")
    n = walk.n_frames
    lengths = np.broadcast_to(morph.lengths, (n, morph.lengths.size)).copy()
    before = decode(walk.poses, lengths)
    ground = Stairs(rise_m=0.12, run_m=0.35, steps=6, start_m=0.5)
    ankles = before.positions[:, [3, 7]]
    targets = ankles.copy()
    targets[..., 2] = ground.height(ankles[..., :2]) + morph["ankle_height_l"]
    weights = walk.contacts().astype(float)
    h1 = before.positions[:, 0, 2] + ground.height(before.positions[:, 0, :2])
    adapted = adapt_to_ground(walk.poses, lengths, targets, weights, h1)
    after = decode(adapted, lengths).positions
    assert np.all(np.isfinite(after))
    assert np.all(after[:, 0, 2] <= h1 + 1e-12)
    reach = MAX_LEG_EXTENSION * (morph["thigh_l"] + morph["shank_l"])
    hips = after[:, [1, 5]]
    reachable = np.linalg.norm(targets - hips, axis=-1) <= reach + 1e-9
    err = np.linalg.norm(after[:, [3, 7]] - targets, axis=-1)
    in_contact = weights == 1.0
    assert in_contact.any() and err[in_contact & reachable].max() < 1e-9
    lengths_after = bone_lengths_of(after)
    for k, (a, _b) in enumerate(BONE_JOINTS):
        if a >= 0:
            assert np.abs(lengths_after[:, k] - morph.lengths[k]).max() < 1e-9


def test_unreachable_target_stretches_the_leg_towards_it():
    walk = import_bvh(MOTIONS_DIR / "idle.bvh")
    morph = Morphology.preset("adult_male")
    poses = walk.poses.take(slice(0, 1))
    lengths = morph.lengths[None]
    before = decode(poses, lengths).positions
    target = before[:, [3, 7]].copy()
    target[0, 0, :2] += [3.0, 0.0]  # 3 m ahead: neither the pelvis nor the root reaches it
    after = decode(adapt_to_ground(poses, lengths, target, np.ones((1, 2)),
                                   before[:, 0, 2]), lengths).positions
    hip, ankle = after[0, 1], after[0, 3]
    leg = morph["thigh_l"] + morph["shank_l"]
    assert abs(np.linalg.norm(ankle - hip) - MAX_LEG_EXTENSION * leg) < 1e-9
    direction = (target[0, 0] - hip) / np.linalg.norm(target[0, 0] - hip)
    assert np.dot((ankle - hip) / np.linalg.norm(ankle - hip), direction) > 1 - 1e-9
    # the root follows by at most its bound (a glitch, not a footprint: the body never jumps)
    moved = np.linalg.norm(after[0, 0, :2] - before[0, 0, :2])
    assert moved == pytest.approx(MAX_ROOT_FOLLOW_PER_REACH * MAX_LEG_EXTENSION * leg, abs=1e-9)


def test_a_footprint_left_behind_by_a_body_lying_down_moves_the_root_not_the_foot():
    """A body lying on the ground (pelvis 0.18 m up, the legs along the floor) whose planted
    ankle is 0.1 m beyond the leg's reach: the pelvis cannot come lower, so the root moves
    towards the footprint (paper §9) by what the leg lacks, and the ankle lands on it."""
    walk = import_bvh(MOTIONS_DIR / "idle.bvh")
    morph = Morphology.preset("adult_male")
    poses = walk.poses.take(slice(0, 1))
    lengths = morph.lengths[None]
    before = decode(poses, lengths).positions
    leg = morph["thigh_l"] + morph["shank_l"]
    hip = before[0, 1]
    target = before[:, [3, 7]].copy()
    target[0, 0] = hip + [MAX_LEG_EXTENSION * leg + 0.1, 0.0, 0.0]
    after = decode(adapt_to_ground(poses, lengths, target, np.array([[1.0, 0.0]]),
                                   before[:, 0, 2]), lengths).positions
    np.testing.assert_allclose(after[0, 3], target[0, 0], atol=1e-9)
    np.testing.assert_allclose(after[0, 0] - before[0, 0], [0.1, 0.0, 0.0], atol=1e-9)


def test_legs_without_contact_go_to_their_targets_and_do_not_lower_the_pelvis():
    walk = import_bvh(MOTIONS_DIR / "walk.bvh")
    morph = Morphology.preset("adult_male")
    poses = walk.poses.take(slice(0, 40))
    lengths = np.broadcast_to(morph.lengths, (40, morph.lengths.size))
    before = decode(poses, lengths).positions
    raised = before[:, 0, 2] + 0.10
    targets = before[:, [3, 7]] + [0.0, 0.0, 0.10]  # the free feet ride along with the pelvis
    after = decode(adapt_to_ground(poses, lengths, targets, np.zeros((40, 2)), raised),
                   lengths).positions
    np.testing.assert_allclose(after[:, 0, 2], raised, atol=1e-12)
    np.testing.assert_allclose(after[:, [3, 7]], targets, atol=1e-9)


@pytest.mark.parametrize(("ground", "passes"), [
    (Plane(0.02), 1), (Slope(0.15, -0.1), 2), (Bumps(0.04, 2.5, 3.0), 3),
    (Combined((Bumps(0.04, 2.5, 3.0), Slope(0.05, 0.02))), 3), (Bumps(0.06, 1.2, 0.9), 3)],
    ids=["plane", "slope", "bench_bumps", "bumps_on_slope", "steep_bumps"])
def test_a_toe_under_the_ground_is_pitched_onto_it_in_a_few_passes(ground, passes):
    """The secant steps of ``pitched``: one pass on a plane, two on a slope, three on bumps
    (the bench's, or of grade 0.42) put every toe end of 500 feet (toes up to 15 cm under the
    ground) within TOE_TOLERANCE_M of its clearance (a fixed point ignoring how the ground
    moves under the end left 6 um after three passes on the bench's bumps)."""
    rng = np.random.default_rng(3607)
    n = 500
    ankle = np.column_stack([rng.uniform(-3.0, 3.0, (n, 2)), np.zeros(n)])
    ankle[:, 2] = ground.height(ankle[:, :2]) + rng.uniform(0.06, 0.10, n)
    heading = rng.uniform(-np.pi, np.pi, n)
    pitch = rng.uniform(-0.9, -0.2, n)  # the toe well under the ankle: most toes go under
    d = np.column_stack([np.cos(heading) * np.cos(pitch), np.sin(heading) * np.cos(pitch),
                         np.sin(pitch)])
    foot, clearance = rng.uniform(0.12, 0.2, n), np.full(n, 0.025)

    def deficit(direction):
        toe = ankle + foot[:, None] * direction
        return ground.height(toe[:, :2]) + clearance - toe[:, 2]

    assert (deficit(d) > 0.01).sum() > n // 4
    assert deficit(pitched(ground, ankle, d, foot, 1.0, clearance, passes)).max() \
        <= TOE_TOLERANCE_M
