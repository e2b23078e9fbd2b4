"""Rotation conventions, pinned: scalar-last quaternions, column-vector matrices, BVH Euler."""

import numpy as np
import pytest

from ecs_anim.core.rotations import (
    axis_angle,
    cross_matrix,
    euler_to_matrix,
    frame_from_axes,
    matrix_from_quat,
    matrix_to_euler,
    quat_from_matrix,
    rot_axis,
    rotation_between,
    slerp,
)

ORDERS = ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]


def test_quaternion_is_scalar_last_and_acts_on_column_vectors():
    q = np.array([0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4)])  # +90 deg about Z
    m = matrix_from_quat(q)
    np.testing.assert_allclose(m @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(rot_axis(2, np.pi / 2), m, atol=1e-15)


def test_bvh_euler_is_intrinsic_in_channel_order():
    # "Zrotation Xrotation Yrotation" means Rz @ Rx @ Ry.
    a = np.array([30.0, -20.0, 45.0])
    expected = rot_axis(2, np.radians(30)) @ rot_axis(0, np.radians(-20)) @ rot_axis(1, np.radians(45))
    np.testing.assert_allclose(euler_to_matrix(a, "ZXY"), expected, atol=1e-15)


@pytest.mark.parametrize("order", ORDERS)
def test_euler_round_trip_batched_including_gimbal_lock(order):
    rng = np.random.default_rng(1)
    angles = rng.uniform(-180, 180, (500, 3))
    angles[:20, 1] = 90.0
    angles[20:40, 1] = -90.0
    matrices = euler_to_matrix(angles, order)
    back = euler_to_matrix(matrix_to_euler(matrices, order), order)
    assert np.abs(back - matrices).max() < 1e-12
    single = np.stack([euler_to_matrix(a, order) for a in angles[:10]])
    np.testing.assert_allclose(single, matrices[:10], atol=1e-15)


def test_quaternion_matrix_round_trip():
    rng = np.random.default_rng(2)
    q = rng.normal(size=(1000, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 3] < 0] *= -1
    np.testing.assert_allclose(quat_from_matrix(matrix_from_quat(q)), q, atol=1e-12)


def test_rotation_between_handles_parallel_and_opposite():
    a = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, 1.0, 0]])
    b = np.array([[1.0, 0, 0], [0, 0, -1.0], [1.0, 0, 0]])
    r = rotation_between(a, b)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", r, a), b, atol=1e-12)
    np.testing.assert_allclose(r @ np.swapaxes(r, 1, 2), np.broadcast_to(np.eye(3), r.shape), atol=1e-12)


def test_cross_matrix_is_the_cross_product():
    rng = np.random.default_rng(3)
    k, v = rng.normal(size=(2, 50, 3))
    np.testing.assert_allclose(np.einsum("nij,nj->ni", cross_matrix(k), v), np.cross(k, v),
                               atol=1e-14)


def test_axis_angle_matches_coordinate_axes_and_quaternions():
    rng = np.random.default_rng(4)
    angle = rng.uniform(-np.pi, np.pi, 200)
    for axis in range(3):
        unit = np.zeros((200, 3))
        unit[:, axis] = 1.0
        np.testing.assert_allclose(axis_angle(unit, angle), rot_axis(axis, angle), atol=1e-15)
    axes = rng.normal(size=(200, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    quat = np.concatenate([np.sin(angle / 2)[:, None] * axes, np.cos(angle / 2)[:, None]], axis=1)
    batch = axis_angle(axes, angle)
    np.testing.assert_allclose(batch, matrix_from_quat(quat), atol=1e-14)
    single = np.stack([axis_angle(axes[i], angle[i]) for i in range(10)])
    np.testing.assert_allclose(single, batch[:10], atol=1e-15)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", batch, axes), axes, atol=1e-14)


def test_frame_from_axes_is_right_handed_with_fallback():
    f = frame_from_axes(np.array([0.0, 0, 1]), np.array([0.0, 0, 2]), 2, 1,
                        fallback_secondary=np.array([1.0, 0, 0]))
    np.testing.assert_allclose(np.linalg.det(f), 1.0)
    np.testing.assert_allclose(f[:, 1], [1.0, 0, 0])


def test_slerp_midpoint():
    q0 = np.array([0.0, 0, 0, 1])
    q1 = np.array([0.0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)])
    mid = slerp(q0, q1, 0.5)
    np.testing.assert_allclose(matrix_from_quat(mid), rot_axis(2, np.pi / 4), atol=1e-12)
