"""Point-to-plane ICP against a VoxelMap: convergence, its Hessian (parameterisation, degeneracy) and edge cases."""
import numpy as np
from scipy.spatial.transform import Rotation
from street_scene import make_transform, make_world, seen_from

from benchmarks.metrics import relative_error
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.steps.refine import point_to_plane_icp


def map_of(points, voxel_size=0.5, per_voxel=20):
    voxel_map = VoxelMap(voxel_size, per_voxel)
    voxel_map.update(points, np.zeros(3))
    return voxel_map




def test_icp_removes_a_small_residual_error():
    world = make_world(n=20000)
    truth = make_transform(yaw=0.02, t=(0.3, -0.1, 0.05))
    source = seen_from(world, truth)[::4]
    start = truth @ make_transform(yaw=np.radians(1.0), t=(0.08, 0.05, -0.03), roll=0.005)
    result = point_to_plane_icp(map_of(world), source, start, 1.0, 20)
    before, after = relative_error(start, truth), relative_error(result.T_target_source, truth)
    assert after[0] < 0.005 and after[1] < 0.02, (before, after)
    assert 0 < result.iterations < 20 and result.n_pairs > 4000 and result.residual_variance < 1e-4


def test_the_polish_stops_once_a_step_moves_the_scan_less_than_its_convergence():
    """``convergence`` bounds a step's motion of the scan (translation + RMS range x rotation): the polish that
    stops there lies within a few of those from the one that spends its whole budget."""
    world = make_world(n=20000)
    truth = make_transform(yaw=0.02, t=(0.3, -0.1, 0.05))
    source = seen_from(world, truth)[::4]
    start = truth @ make_transform(yaw=np.radians(1.5), t=(0.08, 0.05, -0.03), roll=0.005)
    settled = point_to_plane_icp(map_of(world), source, start, 1.0, 40, convergence=1e-3)
    exhaustive = point_to_plane_icp(map_of(world), source, start, 1.0, 40, convergence=0.0)
    lever = np.sqrt(np.mean(np.sum(source ** 2, axis=1)))
    gap_m, gap_deg = relative_error(settled.T_target_source, exhaustive.T_target_source)
    assert settled.iterations < exhaustive.iterations == 40
    assert gap_m + lever * np.radians(gap_deg) < 3e-3, (gap_m, gap_deg, lever)


def test_zero_iterations_returns_the_initial_estimate():
    world = make_world(n=8000)
    start = make_transform(yaw=0.01, t=(0.1, 0.0, 0.0))
    result = point_to_plane_icp(map_of(world), world[:2000], start, 1.0, 0)
    np.testing.assert_array_equal(result.T_target_source, start)
    assert result.iterations == 0 and result.n_pairs > 0 and result.hessian.shape == (6, 6)


def test_too_few_pairs_keep_the_estimate():
    world = make_world(n=8000)
    start = make_transform(t=(500.0, 0.0, 0.0))
    result = point_to_plane_icp(map_of(world), world[:2000], start, 1.0, 10)
    np.testing.assert_array_equal(result.T_target_source, start)
    assert result.iterations == 0 and result.n_pairs == 0


def corridor(rng, n=12000):
    """Two parallel walls (y = +-2) and a floor (z = 0) along x, open at both ends."""
    x = rng.uniform(-30.0, 30.0, n)
    side = rng.integers(0, 3, n)
    y = np.where(side == 0, -2.0, np.where(side == 1, 2.0, rng.uniform(-2.0, 2.0, n)))
    z = np.where(side == 2, 0.0, rng.uniform(0.0, 3.0, n))
    return np.c_[x, y, z] + 0.002 * rng.normal(size=(n, 3))


def test_corridor_hessian_is_blind_to_translation_along_it():
    rng = np.random.default_rng(0)
    voxel_map = map_of(corridor(rng))
    result = point_to_plane_icp(voxel_map, corridor(rng, 4000), np.eye(4), 0.5, 0)
    eigenvalues, eigenvectors = np.linalg.eigh(result.hessian)
    assert abs(eigenvectors[3, 0]) > 0.999, eigenvectors[:, 0]  # the weakest direction: [w, v] = v_x
    translation = np.linalg.eigvalsh(result.hessian[3:, 3:])
    assert translation[0] < 0.01 * translation[-1], translation  # wall-floor corners leave a little


def brute_force_normal_equations(voxel_map, source, T, max_distance, kernel_scale):
    """J^T W J and J^T W r in numpy, with J = [(R p) x n, n] (rotation about the source origin)."""
    lever = source @ T[:3, :3].T
    moved = lever + T[:3, 3]
    dist, index = voxel_map.nearest(moved, max_distance)
    ok = np.isfinite(dist) & (voxel_map.planarity[np.maximum(index, 0)] > 0)
    q, n, planarity = voxel_map.points[index[ok]], voxel_map.normals[index[ok]], voxel_map.planarity[index[ok]]
    r = np.einsum("ij,ij->i", moved[ok] - q, n)
    w = planarity * (kernel_scale ** 2 / (kernel_scale ** 2 + r ** 2)) ** 2
    jacobian = np.hstack([np.cross(lever[ok], n), n])
    return jacobian.T @ (w[:, None] * jacobian), jacobian.T @ (w * r), np.sum(w * r * r) / np.sum(w), int(ok.sum())


def test_hessian_is_j_t_w_j_of_the_returned_estimate():
    rng = np.random.default_rng(1)
    world = make_world(n=6000)
    voxel_map = map_of(world + 0.01 * rng.normal(size=world.shape))
    truth = make_transform(yaw=0.3, t=(12.0, -7.0, 0.5))  # far from the origin: R p and R p + t differ a lot
    source = seen_from(world, truth)[:1500]
    start = truth @ make_transform(yaw=0.01, t=(0.05, 0.03, 0.0))
    for iters in (0, 3):
        result = point_to_plane_icp(voxel_map, source, start, 0.8, iters, kernel_scale=0.2, convergence=0.0)
        assert result.iterations == iters
        hessian, _, variance, n_pairs = brute_force_normal_equations(voxel_map, source, result.T_target_source,
                                                                     0.8, 0.2)
        np.testing.assert_allclose(result.hessian, hessian, rtol=1e-9, atol=1e-9)
        assert result.n_pairs == n_pairs
        assert np.isclose(result.residual_variance, variance, rtol=1e-9)


def test_a_step_follows_the_brute_force_gauss_newton_step():
    """One iteration = R <- exp([w]x) R, t <- t + v with [w, v] = -H^-1 g of the numpy reference."""
    rng = np.random.default_rng(2)
    world = make_world(n=6000)
    voxel_map = map_of(world + 0.01 * rng.normal(size=world.shape))
    truth = make_transform(yaw=-0.4, t=(-9.0, 5.0, 0.2))
    source = seen_from(world, truth)[:1500]
    start = truth @ make_transform(yaw=0.01, t=(0.05, -0.04, 0.02))
    hessian, gradient, _, _ = brute_force_normal_equations(voxel_map, source, start, 0.8, 0.2)
    step = np.linalg.solve(hessian, -gradient)
    expected = np.eye(4)
    expected[:3, :3] = Rotation.from_rotvec(step[:3]).as_matrix() @ start[:3, :3]
    expected[:3, 3] = start[:3, 3] + step[3:]
    result = point_to_plane_icp(voxel_map, source, start, 0.8, 1, kernel_scale=0.2, convergence=0.0)
    np.testing.assert_allclose(result.T_target_source, expected, atol=1e-9)


def test_a_single_plane_moves_only_what_it_constrains():
    """Rank-3 Hessian: the solve stays defined, the offset along the normal goes, the in-plane one stays."""
    rng = np.random.default_rng(3)
    plane = np.c_[rng.uniform(-10.0, 10.0, (5000, 2)), np.zeros(5000)]
    start = make_transform(t=(0.1, 0.2, 0.05))
    result = point_to_plane_icp(map_of(plane), plane[::5], start, 1.0, 10)
    np.testing.assert_allclose(result.T_target_source[:3, 3], [0.1, 0.2, 0.0], atol=1e-9)
    assert np.sum(np.linalg.eigvalsh(result.hessian) > 1e-6) == 3


def test_a_coarse_stride_reaches_the_same_answer_and_reports_the_information_of_every_point():
    world = make_world(n=20000)
    voxel_map = map_of(world)
    truth = make_transform(yaw=0.02, t=(0.3, -0.1, 0.05))
    source = seen_from(world, truth)[::4]
    start = truth @ make_transform(yaw=np.radians(1.5), t=(0.12, 0.05, -0.03), roll=0.005)
    full = point_to_plane_icp(voxel_map, source, start, 1.0, 30)
    strided = point_to_plane_icp(voxel_map, source, start, 1.0, 30, coarse_stride=4)
    assert within_mm(strided.T_target_source, full.T_target_source) and within_mm(strided.T_target_source, truth, 5)
    hessian, _, variance, n_pairs = brute_force_normal_equations(voxel_map, source, strided.T_target_source, 1.0,
                                                                 1.0 / 3.0)
    np.testing.assert_allclose(strided.hessian, hessian, rtol=1e-9, atol=1e-9)  # all points, not the stride's
    assert strided.n_pairs == n_pairs > 4000


def test_a_budget_spent_on_the_stride_still_ends_on_every_point():
    world = make_world(n=20000)
    voxel_map = map_of(world)
    truth = make_transform(yaw=0.02, t=(0.3, -0.1, 0.05))
    source = seen_from(world, truth)[::4]
    result = point_to_plane_icp(voxel_map, source, truth @ make_transform(t=(0.2, 0.0, 0.0)), 1.0, 1,
                                coarse_stride=4)
    _, _, _, n_pairs = brute_force_normal_equations(voxel_map, source, result.T_target_source, 1.0, 1.0 / 3.0)
    assert result.iterations == 1 and result.n_pairs == n_pairs


def within_mm(T_a, T_b, mm=1.0):
    metres, degrees = relative_error(T_a, T_b)
    return metres < mm * 1e-3 and degrees < 0.05
