import numpy as np
import torch

from cemnet_ros.core.geometry_torch import euler_to_matrix, transform_points
from cemnet_ros.core.icp import point_to_point_icp
from cemnet_ros.core.icp_torch import batch_icp
from cemnet_ros.core.lattice_rewards import best_rotation


def test_batched_icp_recovers_small_motions(bracket):
    src = torch.tensor(bracket[:512])
    rot = euler_to_matrix(torch.tensor([[0.05, -0.03, 0.02], [-0.04, 0.02, 0.03]], dtype=torch.float64))
    trans = torch.tensor([[0.02, -0.01, 0.03], [0.0, 0.03, -0.02]], dtype=torch.float64)
    tgt = transform_points(src, rot[:1], trans[:1])  # motion 0 is the true one
    eye = torch.eye(3, dtype=torch.float64).expand(2, 3, 3)
    r, t = batch_icp(src[None], tgt, eye, torch.zeros(2, 3, dtype=torch.float64), steps=30)
    torch.testing.assert_close(r[0], rot[0], atol=1e-6, rtol=0)
    torch.testing.assert_close(t[0], trans[0], atol=1e-6, rtol=0)
    assert torch.det(r).sub(1).abs().max() < 1e-9


def test_point_to_point_icp_converges(bracket):
    src = bracket[:512]
    rot = euler_to_matrix(torch.tensor([0.04, 0.02, -0.03], dtype=torch.float64)).numpy()
    trans = np.array([0.02, -0.02, 0.01])
    tgt = src @ rot.T + trans
    r, t = point_to_point_icp(src, tgt, np.eye(3), np.zeros(3), max_iterations=30, max_distance=0.2)
    np.testing.assert_allclose(r, rot, atol=1e-6)
    np.testing.assert_allclose(t, trans, atol=1e-6)


def _kabsch(cov: np.ndarray) -> np.ndarray:
    u, _, vt = np.linalg.svd(cov)
    fix = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))])
    return vt.T @ fix @ u.T


def test_quaternion_rotation_of_the_cpu_icp_equals_kabsch_with_reflection_fix():
    rng = np.random.default_rng(0)
    covariances = list(rng.normal(size=(200, 3, 3)))  # about half need the reflection fix
    for i in range(200):  # noisy correspondences of a true motion, and flat (planar) sets
        x = rng.normal(size=(40, 3)) * ([1.0, 1.0, 1e-3] if i % 2 else 1.0)
        rot = euler_to_matrix(torch.tensor(rng.uniform(-np.pi, np.pi, 3))).numpy()
        y = x @ rot.T + rng.normal(scale=0.01, size=x.shape)
        covariances.append((x - x.mean(0)).T @ (y - y.mean(0)))
        if i % 2 == 0:
            np.testing.assert_allclose(best_rotation(covariances[-1]), rot, atol=0.05)
    for cov in covariances:
        r = best_rotation(cov)
        np.testing.assert_allclose(r, _kabsch(cov), atol=1e-8)
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-10)
        assert abs(np.linalg.det(r) - 1.0) < 1e-10
