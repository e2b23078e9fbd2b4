"""Limb steps of the constraint solver (paper §9, fig. 11): a limb root brought within reach."""

import numpy as np

from ecs_anim.solver.steps import bring_within_reach


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
