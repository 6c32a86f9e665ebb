import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from cemnet_ros.core.geometry import (
    action_to_matrix_np,
    apply_transform,
    euler_to_matrix_np,
    matrix_to_action_np,
    matrix_to_euler_np,
    procrustes_np,
    rigid_transform,
    rotation_angle_deg,
)
from cemnet_ros.core.geometry_torch import euler_to_matrix, matrix_to_euler, procrustes, transform_points


def test_euler_convention_matches_scipy_zyx():
    angles = np.array([[0.3, -0.2, 0.7], [1.2, 0.4, -2.0], [0.0, 0.0, 0.0]])
    expected = Rotation.from_euler("zyx", angles).as_matrix()
    np.testing.assert_allclose(euler_to_matrix_np(angles), expected, atol=1e-12)


def test_matrix_to_euler_inverts_within_range():
    rng = np.random.default_rng(0)
    angles = rng.uniform([-np.pi, -np.pi / 2 + 0.01, -np.pi], [np.pi, np.pi / 2 - 0.01, np.pi], (100, 3))
    back = matrix_to_euler(euler_to_matrix(torch.tensor(angles))).numpy()
    np.testing.assert_allclose(back, angles, atol=1e-9)


def test_matrix_to_action():
    action = np.array([0.1, -0.3, 0.5, 1.0, -2.0, 0.25])
    transform = np.eye(4)
    transform[:3, :3] = euler_to_matrix_np(action[:3])
    transform[:3, 3] = action[3:]
    np.testing.assert_allclose(matrix_to_action_np(transform), action, atol=1e-12)
    np.testing.assert_array_equal(action_to_matrix_np(action), transform)
    np.testing.assert_array_equal(rigid_transform(transform[:3, :3], action[3:]), transform)


def test_rotation_angle():
    assert rotation_angle_deg(np.eye(3)) == pytest.approx(0.0, abs=1e-6)
    assert rotation_angle_deg(Rotation.from_euler("z", 30, degrees=True).as_matrix()) == pytest.approx(30.0)
    a, b = (Rotation.from_euler("zyx", angles, degrees=True).as_matrix() for angles in ([10, 20, 30], [10, 20, 37]))
    assert rotation_angle_deg(a.T @ b) == pytest.approx(7.0)  # the angle between two rotations


def test_procrustes_np_exact_no_reflection_and_checks_shapes(bracket):
    T_target_source = action_to_matrix_np(np.array([0.7, -0.35, 1.3, 0.3, -0.1, 0.7]))
    r, t = procrustes_np(bracket, apply_transform(T_target_source, bracket))
    np.testing.assert_allclose(rigid_transform(r, t), T_target_source, atol=1e-10)
    mirrored = bracket * np.array([1.0, 1.0, -1.0])  # best orthogonal fit is a reflection
    r, _ = procrustes_np(bracket, mirrored)
    assert abs(np.linalg.det(r) - 1.0) < 1e-10
    with pytest.raises(ValueError, match="equal shape"):
        procrustes_np(bracket, bracket[:10])


def test_procrustes_recovers_motion_and_never_reflects():
    rng = np.random.default_rng(1)
    src = torch.tensor(rng.standard_normal((2, 50, 3)))
    rot = euler_to_matrix(torch.tensor([[0.4, 0.2, -0.3], [2.5, -1.0, 0.1]], dtype=torch.float64))
    trans = torch.tensor([[0.1, 0.2, 0.3], [-1.0, 0.0, 2.0]], dtype=torch.float64)
    r, t = procrustes(src, transform_points(src, rot, trans))
    torch.testing.assert_close(r, rot)
    torch.testing.assert_close(t, trans)
    # A mirrored target must still give a proper rotation (det +1).
    mirrored = src * torch.tensor([1.0, 1.0, -1.0], dtype=src.dtype)
    r, _ = procrustes(src, mirrored)
    np.testing.assert_allclose(torch.det(r).numpy(), 1.0, atol=1e-9)


def test_numpy_twins_match_the_torch_functions():
    angles = np.random.default_rng(3).uniform(-1.5, 1.5, (20, 3))
    torch_rot = euler_to_matrix(torch.as_tensor(angles)).numpy()
    np.testing.assert_allclose(euler_to_matrix_np(angles), torch_rot, atol=1e-12)
    np.testing.assert_allclose(matrix_to_euler_np(torch_rot), matrix_to_euler(torch.as_tensor(torch_rot)).numpy(),
                               atol=1e-12)
