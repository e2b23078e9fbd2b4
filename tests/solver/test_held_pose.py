"""A character the budget solves every few ticks keeps its last solve's correction in between
(:mod:`ecs_anim.solver.held_pose`)."""

from __future__ import annotations

import numpy as np
import pytest

from ecs_anim.solver.held_pose import HELD_FIELDS, HeldCorrections

HALF_TURN_Z = np.array([0.0, 0.0, np.sin(0.2), np.cos(0.2)])  # 0.4 rad = 22.918° about z


def _turned_by_z(q):
    """Quaternions (r, 4) left-multiplied by :data:`HALF_TURN_Z`."""
    x, y, z, w = HALF_TURN_Z
    qx, qy, qz, qw = q.T
    return np.stack([w * qx + x * qw + y * qz - z * qy, w * qy - x * qz + y * qw + z * qx,
                     w * qz + x * qy - y * qx + z * qw, w * qw - x * qx - y * qy - z * qz], axis=1)


def _turn_deg(a, b):
    """The angle between unit quaternions (..., 4), degrees."""
    return np.degrees(2.0 * np.arccos(np.clip(np.abs(np.sum(a * b, axis=-1)), 0.0, 1.0)))


def _kept(idle):
    """Frame 0 of the idle and its "solved" copy (the right arm and the left leg turned 23°,
    the spine and the left leg's fraction shifted, the root moved 22 mm), kept for row 0."""
    motion = idle.poses.take(np.array([0]))
    solved = idle.poses.take(np.array([0]))
    solved.arm_frame[:, 1] = _turned_by_z(solved.arm_frame[:, 1])
    solved.leg_frame[:, 0] = _turned_by_z(solved.leg_frame[:, 0])
    solved.leg_fraction[:, 0] -= 0.02
    solved.spine_points[:, 1] += 0.01
    solved.root_position[:, :2] += (0.02, -0.01)
    held = HeldCorrections()
    held.start_tick(motion, version=0)
    held.keep(np.array([0]), motion, solved)
    return held, solved


def test_on_the_same_motion_the_correction_gives_the_solved_pose_back(idle):
    held, solved = _kept(idle)
    assert held.known.tolist() == [True]
    again = idle.poses.take(np.array([0]))
    held.put_on(again, np.array([0]))
    for name, value in solved.arrays().items():
        np.testing.assert_allclose(getattr(again, name), value, atol=1e-12, err_msg=name)


def test_later_the_legs_follow_the_motion_and_the_rest_is_held(idle):
    """Put on frame 20: the left leg 23° from that frame's motion and its fraction 0.02 shorter
    (it goes on stepping), the root 22 mm from the motion's; the arms, trunk and head as
    solved."""
    held, solved = _kept(idle)
    later = idle.poses.take(np.array([20]))
    out = idle.poses.take(np.array([20]))
    held.put_on(out, np.array([0]))
    assert _turn_deg(out.leg_frame[0, 0], later.leg_frame[0, 0]) == pytest.approx(22.918, abs=1e-3)
    assert _turn_deg(out.leg_frame[0, 1], later.leg_frame[0, 1]) == pytest.approx(0.0, abs=1e-5)
    assert out.leg_fraction[0, 0] == pytest.approx(later.leg_fraction[0, 0] - 0.02, abs=1e-12)
    moved = np.linalg.norm((out.root_position - later.root_position)[0, :2])
    assert moved == pytest.approx(np.hypot(0.02, 0.01), abs=1e-12)
    for name in HELD_FIELDS:
        np.testing.assert_array_equal(getattr(out, name), getattr(solved, name), err_msg=name)
    np.testing.assert_allclose(np.linalg.norm(out.foot_dir, axis=-1), 1.0, atol=1e-12)


def test_a_new_store_forgets_every_correction(idle):
    held, _ = _kept(idle)
    held.start_tick(idle.poses.take(np.array([0])), version=0)
    assert held.known.all()
    held.start_tick(idle.poses.take(np.array([0])), version=1)
    assert not held.known.any()
