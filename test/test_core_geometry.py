import numpy as np
import torch
from scipy.spatial.transform import Rotation

from cemnet_ros.core.geometry import euler_to_matrix_np, matrix_to_action_np, matrix_to_euler_np
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
