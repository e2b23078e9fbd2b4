"""Limb steps of the constraint solver (paper §9, fig. 11): reach, swivel, priorities."""

import numpy as np

from ecs_anim.rotations import frame_from_axes
from ecs_anim.solver import bring_within_reach, middle_joint, reach, swivel

RNG = np.random.default_rng(11)
N = 500


def _limbs():
    root = RNG.normal(size=(N, 3))
    upper = RNG.uniform(0.2, 0.4, N)
    lower = RNG.uniform(0.2, 0.4, N)
    frame = frame_from_axes(RNG.normal(size=(N, 3)), RNG.normal(size=(N, 3)), 2, 1)
    return root, frame, upper, lower


def test_reachable_targets_are_met_and_bones_keep_their_lengths():
    root, frame, upper, lower = _limbs()
    direction = RNG.normal(size=(N, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    dist = RNG.uniform(np.abs(upper - lower) + 1e-3, upper + lower - 1e-3)
    target = root + direction * dist[:, None]
    new_frame, fraction, end = reach(root, frame, upper, lower, target)
    assert np.abs(end - target).max() < 1e-12
    mid = middle_joint(root, new_frame, upper, lower, fraction)
    np.testing.assert_allclose(np.linalg.norm(mid - root, axis=1), upper, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(end - mid, axis=1), lower, atol=1e-12)


def test_unreachable_target_stretches_towards_it_with_the_geometric_minimum_error():
    root, frame, upper, lower = _limbs()
    direction = RNG.normal(size=(N, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    target = root + direction * (upper + lower + RNG.uniform(0.01, 2.0, N))[:, None]
    _, fraction, end = reach(root, frame, upper, lower, target)
    error = np.linalg.norm(end - target, axis=1)
    np.testing.assert_allclose(error, np.linalg.norm(target - root, axis=1) - (upper + lower), atol=1e-12)
    np.testing.assert_allclose(fraction, 1.0)
    # Stable: solving again from the result changes nothing (no jitter from tick to tick).
    again = reach(root, reach(root, frame, upper, lower, target)[0], upper, lower, target)
    assert np.abs(again[2] - end).max() < 1e-12


def test_wrist_high_elbow_low_both_reachable_both_met():
    root, frame, upper, lower = _limbs()
    # Targets from a real configuration: a wrist and an elbow that belong together.
    truth = frame_from_axes(RNG.normal(size=(N, 3)), RNG.normal(size=(N, 3)), 2, 1)
    true_fraction = RNG.uniform(0.5, 0.95, N)
    wrist_target = root + truth[:, :, 2] * (true_fraction * (upper + lower))[:, None]
    elbow_target = middle_joint(root, truth, upper, lower, true_fraction)
    new_frame, fraction, end = reach(root, frame, upper, lower, wrist_target)
    new_frame = swivel(root, new_frame, elbow_target)
    elbow = middle_joint(root, new_frame, upper, lower, fraction)
    assert np.abs(end - wrist_target).max() < 1e-12
    assert np.abs(elbow - elbow_target).max() < 1e-9
    # The swivel keeps the wrist: the end is along the unchanged z axis.
    np.testing.assert_allclose(new_frame[:, :, 2] * (fraction * (upper + lower))[:, None] + root,
                               wrist_target, atol=1e-12)


def test_elbow_target_off_the_circle_gets_the_closest_point():
    root, frame, upper, lower = _limbs()
    wrist_target = root + frame[:, :, 2] * (0.8 * (upper + lower))[:, None]
    elbow_target = root + RNG.normal(size=(N, 3))
    new_frame, fraction, _ = reach(root, frame, upper, lower, wrist_target)
    best = middle_joint(root, swivel(root, new_frame, elbow_target), upper, lower, fraction)
    best_error = np.linalg.norm(best - elbow_target, axis=1)
    # No other swivel angle does better (sampled circle).
    for angle in np.linspace(0, 2 * np.pi, 36, endpoint=False):
        c, s = np.cos(angle), np.sin(angle)
        turned = new_frame.copy()
        turned[:, :, 1] = c * new_frame[:, :, 1] - s * new_frame[:, :, 0]
        turned[:, :, 0] = c * new_frame[:, :, 0] + s * new_frame[:, :, 1]
        other = middle_joint(root, turned, upper, lower, fraction)
        assert np.all(best_error <= np.linalg.norm(other - elbow_target, axis=1) + 1e-12)


def test_swivel_weight_and_degenerate_target_are_finite():
    root, frame, _upper, _lower = _limbs()
    on_axis = root + frame[:, :, 2]
    same = swivel(root, frame, on_axis)
    np.testing.assert_allclose(same, frame, atol=1e-12)
    half = swivel(root, frame, root + RNG.normal(size=(N, 3)), weight=np.full(N, 0.5))
    assert np.all(np.isfinite(half))
    np.testing.assert_allclose(np.einsum("nij,nik->njk", half, half), np.broadcast_to(np.eye(3), (N, 3, 3)), atol=1e-12)


def test_bring_within_reach_turns_the_limb_root_just_enough():
    rng = np.random.default_rng(7)
    n = 400
    base = rng.normal(size=(n, 3))
    root = base + rng.normal(size=(n, 3)) * 0.3
    goal = base + rng.normal(size=(n, 3))
    reach_m = rng.uniform(0.2, 0.8, n)
    turn = bring_within_reach(base, root, goal, reach_m)
    moved = base + np.einsum("kij,kj->ki", turn, root - base)
    a = np.linalg.norm(root - base, axis=1)
    b = np.linalg.norm(goal - base, axis=1)
    before = np.linalg.norm(root - goal, axis=1)
    after = np.linalg.norm(moved - goal, axis=1)
    np.testing.assert_allclose(np.einsum("kij,kil->kjl", turn, turn), np.broadcast_to(np.eye(3), (n, 3, 3)), atol=1e-12)
    within = before <= reach_m
    np.testing.assert_allclose(after[within], before[within], atol=1e-12)  # no turn needed
    can = ~within & (np.abs(b - a) <= reach_m)
    np.testing.assert_allclose(after[can], reach_m[can], atol=1e-9)  # exactly within reach
    cannot = ~within & ~can
    np.testing.assert_allclose(after[cannot], np.abs(b - a)[cannot], atol=1e-9)  # as near as it gets
    # The smallest such turn: the root's angle about the base changed by no more than needed.
    cos_needed = np.clip((a**2 + b**2 - reach_m**2) / (2 * a * b), -1, 1)
    angle_before = np.arccos(np.clip(np.sum((root - base) * (goal - base), 1) / (a * b), -1, 1))
    angle_after = np.arccos(np.clip(np.sum((moved - base) * (goal - base), 1) / (a * b), -1, 1))
    np.testing.assert_allclose(angle_after[can], np.arccos(cos_needed[can]), atol=1e-9)
    assert np.all(angle_after <= angle_before + 1e-12)
    capped = bring_within_reach(base, root, goal, reach_m, max_angle=0.05)
    moved_capped = base + np.einsum("kij,kj->ki", capped, root - base)
    step = np.arccos(np.clip(np.sum((moved_capped - base) * (root - base), 1) / a**2, -1, 1))
    assert np.all(step <= 0.05 + 1e-9)
