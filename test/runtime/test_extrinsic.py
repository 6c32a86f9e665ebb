"""Sensor odometry -> base odometry: poses, relative motions and covariances under an extrinsic."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from cemnet_ros.runtime.extrinsic import BaseFrame, in_body_axes, pose_from_xyz_rpy

T_BS = pose_from_xyz_rpy((0.4, -0.2, 1.5, 0.02, -0.03, 0.7))


def _random_pose(rng):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rng.normal(0, 0.5, 3)).as_matrix()
    T[:3, 3] = rng.normal(0, 5, 3)
    return T


def test_xyz_rpy_follows_ros():
    T = pose_from_xyz_rpy((1, 2, 3, 0.1, 0.2, 0.3))
    np.testing.assert_allclose(T[:3, :3], Rotation.from_euler("ZYX", [0.3, 0.2, 0.1]).as_matrix(), atol=1e-12)
    np.testing.assert_allclose(T[:3, 3], [1, 2, 3])


def test_base_pose_starts_at_the_origin_and_inverts():
    frame, rng = BaseFrame(T_BS), np.random.default_rng(0)
    np.testing.assert_allclose(frame.pose(np.eye(4)), np.eye(4), atol=1e-12)  # odom = base at the first scan
    T = _random_pose(rng)
    np.testing.assert_allclose(frame.sensor_pose(frame.pose(T)), T, atol=1e-12)
    T2 = _random_pose(rng)
    np.testing.assert_allclose(frame.relative(np.linalg.inv(T) @ T2),
                               np.linalg.inv(frame.pose(T)) @ frame.pose(T2), atol=1e-9)


def _perturbation_about(T, position, v, w):
    """Left perturbation: rotate by w about ``position`` (world axes), then translate by v."""
    D = np.eye(4)
    D[:3, :3] = Rotation.from_rotvec(w).as_matrix()
    D[:3, 3] = position - D[:3, :3] @ position + v
    return D @ T


def test_covariance_moves_to_the_base_with_the_lever_arm():
    """Sample sensor perturbations with a covariance; the base's perturbations have the mapped covariance."""
    frame, rng = BaseFrame(T_BS), np.random.default_rng(1)
    T_s = _random_pose(rng)
    A = rng.normal(size=(6, 6)) * 0.01
    cov_sensor = A @ A.T + np.eye(6) * 1e-6  # ROS order [v, w] about the sensor, sensor0 axes
    samples = rng.multivariate_normal(np.zeros(6), cov_sensor, 20000)
    base = frame.pose(T_s)
    deltas = []
    for s in samples:
        T_b = frame.pose(_perturbation_about(T_s, T_s[:3, 3], s[:3], s[3:]))
        w = Rotation.from_matrix(T_b[:3, :3] @ base[:3, :3].T).as_rotvec()
        v = T_b[:3, 3] - base[:3, 3]  # rotation about the base position: the base's own displacement
        deltas.append(np.r_[v, w])
    empirical = np.cov(np.array(deltas).T)
    predicted = frame.covariance(cov_sensor, T_s)
    assert np.abs(empirical - predicted).max() < 0.05 * np.abs(predicted).max()


def test_body_axes_rotate_both_blocks():
    cov = np.diag([1.0, 2, 3, 4, 5, 6])
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    body = in_body_axes(cov, T)
    np.testing.assert_allclose(np.diag(body), [2, 1, 3, 5, 4, 6], atol=1e-12)
