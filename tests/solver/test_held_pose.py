"""A character the budget solves every few ticks keeps its last solve's correction in between
(:mod:`ecs_anim.solver.held_pose`)."""

from __future__ import annotations

import numpy as np
import pytest

from ecs_anim.solver.held_pose import HeldCorrections, corrected_values, unpack_into
from ecs_anim.solver.joint_speed import DIRECTIONS_AT, SHIFTS_AT, _quat_mul, pack

ARM_R_FRAME = slice(12, 16)  # FRAMES[3]: the right arm's half-plane frame
LEG_L_FRAME = slice(0, 4)  # FRAMES[0]
LEG_L_FRACTION = SHIFTS_AT  # SHIFTS[0]


def _turn_deg(a, b):
    """The angle between unit quaternions (r, 4), degrees."""
    return np.degrees(2.0 * np.arccos(np.clip(np.abs(np.sum(a * b, axis=1)), 0.0, 1.0)))


def test_the_legs_follow_the_motion_and_the_rest_is_held(idle):
    """Kept from one frame of the motion and its corrected copy (the right arm and the left
    leg turned 23°, the spine and the legs' fractions shifted, the root moved), then put on the
    same frame: the corrected pose again. Put on a later frame: the left leg 23° from that
    frame's motion and its fraction shifted the same (it goes on stepping); the arm and the
    spine as solved."""
    then, later = idle.poses.take(np.array([0])), idle.poses.take(np.array([20]))
    solved = idle.poses.take(np.array([0]))
    turn = np.array([[0.0, 0.0, np.sin(0.2), np.cos(0.2)]])
    solved.arm_frame[:, 1] = _quat_mul(turn, solved.arm_frame[:, 1])
    solved.leg_frame[:, 0] = _quat_mul(turn, solved.leg_frame[:, 0])
    solved.leg_fraction[:, 0] -= 0.02
    solved.spine_points[:, 1] += 0.01
    solved.root_position[:, :2] += (0.02, -0.01)
    held = HeldCorrections()
    held.start_tick(version=0, n=1)
    rows = np.array([0])
    held.keep(rows, pack(then), pack(solved), then.root_position, solved.root_position,
              then.root_heading)
    assert held.known.tolist() == [True]
    again = idle.poses.take(np.array([0]))
    held.put_on(again, rows, pack(again))
    np.testing.assert_allclose(pack(again), pack(solved), atol=1e-12)
    np.testing.assert_allclose(again.root_position, solved.root_position, atol=1e-12)
    out = corrected_values(pack(later), pack(then), pack(solved))
    assert abs(_turn_deg(out[:, LEG_L_FRAME], pack(later)[:, LEG_L_FRAME])[0] - 22.918) < 1e-3
    assert out[0, LEG_L_FRACTION] == pytest.approx(pack(later)[0, LEG_L_FRACTION] - 0.02, abs=1e-12)
    np.testing.assert_allclose(out[:, ARM_R_FRAME], pack(solved)[:, ARM_R_FRAME], atol=1e-12)
    np.testing.assert_allclose(out[:, SHIFTS_AT + 4:], pack(solved)[:, SHIFTS_AT + 4:], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(out[:, DIRECTIONS_AT:SHIFTS_AT].reshape(-1, 3),
                                              axis=1), 1.0, atol=1e-12)


def test_a_new_store_forgets_every_correction():
    held = HeldCorrections()
    held.start_tick(version=0, n=2)
    held.known[:] = True
    held.start_tick(version=0, n=2)
    assert held.known.all()
    held.start_tick(version=1, n=2)
    assert not held.known.any()


def test_unpack_is_the_inverse_of_pack(idle):
    poses = idle.poses.take(np.arange(3))
    values = pack(idle.poses.take(np.array([5, 6, 7])))
    unpack_into(poses, np.arange(3), values)
    np.testing.assert_array_equal(pack(poses), values)
