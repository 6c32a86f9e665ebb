"""VoxelMap: capped voxels, pruning, exact nearest neighbours, normals, inlier fraction and sampling."""
import numpy as np
import pytest
from scipy.spatial import cKDTree

from cemnet_ros.pipeline.map.voxel_map import VoxelMap


def test_insert_caps_each_voxel_and_keeps_its_first_points():
    rng = np.random.default_rng(0)
    first = rng.uniform(0.0, 1.0, (3, 3))  # one voxel of 1 m
    voxel_map = VoxelMap(1.0, max_points_per_voxel=5)
    voxel_map.update(first, np.zeros(3))
    voxel_map.update(rng.uniform(0.0, 1.0, (10, 3)), np.zeros(3))
    assert len(voxel_map) == 5 and not voxel_map.empty()
    stored = voxel_map.points
    for p in first:
        assert np.any(np.all(stored == p, axis=1))
    voxel_map.update(rng.uniform(0.0, 1.0, (10, 3)), np.zeros(3))
    assert len(voxel_map) == 5  # full: later points are dropped


def test_many_voxels_are_all_capped():
    points = np.random.default_rng(1).uniform(-20.0, 20.0, (20000, 3))
    voxel_map = VoxelMap(2.0, max_points_per_voxel=3)
    voxel_map.update(points, np.zeros(3))
    cells, per_voxel = np.unique(np.floor(voxel_map.points / 2.0), axis=0, return_counts=True)
    all_cells, offered = np.unique(np.floor(points / 2.0), axis=0, return_counts=True)
    np.testing.assert_array_equal(cells, all_cells)
    np.testing.assert_array_equal(per_voxel, np.minimum(offered, 3))
    assert voxel_map.points.shape == voxel_map.normals.shape == (len(voxel_map), 3)
    assert voxel_map.planarity.shape == (len(voxel_map),)
    voxel_map.clear()
    assert voxel_map.empty() and len(voxel_map) == 0 and voxel_map.points.shape == (0, 3)


def test_prune_removes_far_voxels_and_keeps_near_ones():
    rng = np.random.default_rng(2)
    near, far = rng.uniform(-2.0, 2.0, (500, 3)), rng.uniform(-2.0, 2.0, (500, 3)) + [50.0, 0.0, 0.0]
    voxel_map = VoxelMap(1.0, max_points_per_voxel=1000, max_distance=10.0)
    voxel_map.update(np.vstack([near, far]), np.zeros(3))
    np.testing.assert_array_equal(np.sort(voxel_map.points, axis=0), np.sort(near, axis=0))
    voxel_map.update(np.zeros((0, 3)), np.array([50.0, 0.0, 0.0]))  # the sensor moved away
    assert voxel_map.empty()


def test_pruning_keeps_the_map_consistent():
    """Voxels removed from the middle of the storage and the hash table: the rest is still found exactly."""
    rng = np.random.default_rng(3)
    voxel_map = VoxelMap(0.5, max_points_per_voxel=4, max_distance=6.0)
    for x in np.arange(0.0, 30.0, 2.0):
        voxel_map.update(rng.uniform(-4.0, 4.0, (3000, 3)) + [x, 0.0, 0.0], np.array([x, 0.0, 0.0]))
    points = voxel_map.points
    centres = (np.floor(points / 0.5) + 0.5) * 0.5
    assert np.linalg.norm(centres - [28.0, 0.0, 0.0], axis=1).max() <= 6.0
    query = rng.uniform(-4.0, 4.0, (500, 3)) + [28.0, 0.0, 0.0]
    dist, index = voxel_map.nearest(query, 0.6)
    expected, expected_index = cKDTree(points).query(query, distance_upper_bound=0.6)
    np.testing.assert_array_equal(index, np.where(np.isfinite(expected), expected_index, -1))
    np.testing.assert_allclose(dist, expected)


@pytest.mark.parametrize("max_distance", [0.1, 0.7, 2.5])
def test_nearest_matches_a_kd_tree_within_the_radius(max_distance):
    rng = np.random.default_rng(4)
    voxel_map = VoxelMap(1.0, max_points_per_voxel=8)
    voxel_map.update(rng.uniform(-5.0, 5.0, (4000, 3)), np.zeros(3))
    query = rng.uniform(-7.0, 7.0, (3000, 3))
    dist, index = voxel_map.nearest(query, max_distance)
    expected, expected_index = cKDTree(voxel_map.points).query(query, distance_upper_bound=max_distance)
    found = np.isfinite(expected)
    assert 0 < found.sum() < len(query)
    np.testing.assert_array_equal(np.isfinite(dist), found)
    np.testing.assert_allclose(dist[found], expected[found])
    np.testing.assert_array_equal(index[found], expected_index[found])
    assert np.all(index[~found] == -1)


def test_normals_of_a_plane_are_its_normal_with_high_planarity():
    rng = np.random.default_rng(5)
    n = np.array([1.0, 2.0, 2.0]) / 3.0
    u = np.cross(n, [0.0, 0.0, 1.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    coords = rng.uniform(-5.0, 5.0, (6000, 2))
    plane = coords[:, :1] * u + coords[:, 1:] * v + 0.005 * rng.normal(size=(6000, 1)) * n + [10.0, -3.0, 1.0]
    voxel_map = VoxelMap(1.0, max_points_per_voxel=20)
    voxel_map.update(plane, np.zeros(3))
    np.testing.assert_allclose(np.linalg.norm(voxel_map.normals, axis=1), 1.0)
    assert np.abs(voxel_map.normals @ n).min() > 0.99
    assert np.median(voxel_map.planarity) > 0.75 and voxel_map.planarity.min() >= 0.0


def test_lines_and_blobs_have_low_planarity_and_lone_points_none():
    rng = np.random.default_rng(6)
    line = np.c_[rng.uniform(-5.0, 5.0, 2000), 0.01 * rng.normal(size=(2000, 2))]
    ring = np.c_[rng.uniform(-5.0, 5.0, 2000), np.full(2000, 8.0), 0.01 * rng.normal(size=2000)]  # noise on z only
    blob = rng.normal(size=(2000, 3)) * 0.3 + [20.0, 0.0, 0.0]
    lone = np.array([[-20.0, 5.0, 5.0], [-20.1, 5.0, 5.0]])
    voxel_map = VoxelMap(1.0, max_points_per_voxel=30)
    voxel_map.update(np.vstack([line, ring, blob, lone]), np.zeros(3))
    points, planarity = voxel_map.points, voxel_map.planarity
    assert np.median(planarity[(np.abs(points[:, 0]) < 5.0) & (np.abs(points[:, 1]) < 1.0)]) < 0.2
    assert np.median(planarity[np.abs(points[:, 1] - 8.0) < 1.0]) < 0.2  # a LiDAR ring: no surface
    assert np.median(planarity[points[:, 0] > 15.0]) < 0.5
    np.testing.assert_array_equal(planarity[points[:, 0] < -15.0], 0.0)


def test_inlier_fraction_counts_points_near_the_map_after_the_transform():
    rng = np.random.default_rng(7)
    cloud = rng.uniform(-5.0, 5.0, (3000, 3))
    voxel_map = VoxelMap(1.0, max_points_per_voxel=50)
    voxel_map.update(cloud, np.zeros(3))
    T = np.eye(4)
    T[:3, 3] = [3.0, 0.0, 0.0]
    source = cloud - T[:3, 3]  # T maps it back onto the map
    assert voxel_map.inlier_fraction(source, T, 0.01) == 1.0
    assert voxel_map.inlier_fraction(source, np.eye(4), 0.01) < 0.05
    assert voxel_map.inlier_fraction(np.zeros((0, 3)), T, 0.01) == 0.0


def test_overlap_gives_the_inlier_fraction_and_the_share_within_reach_of_the_map():
    rng = np.random.default_rng(9)
    floor = np.c_[rng.uniform(0.0, 10.0, (4000, 2)), np.zeros(4000)]
    voxel_map = VoxelMap(0.5, max_points_per_voxel=20)
    voxel_map.update(floor, np.zeros(3))
    on_floor = np.c_[rng.uniform(1.0, 9.0, (600, 2)), np.zeros(600)]
    just_above = on_floor[:300] + [0.0, 0.0, 0.3]  # near the floor, off its plane
    off_map = np.c_[rng.uniform(30.0, 40.0, (100, 2)), np.zeros(100)]  # where the map has nothing
    source = np.vstack([on_floor, just_above, off_map])
    fitness, coverage = voxel_map.overlap(source, np.eye(4), 0.5, 0.05, 1.0)
    assert fitness == pytest.approx(600 / 1000) and coverage == pytest.approx(900 / 1000)
    assert fitness == voxel_map.inlier_fraction(source, np.eye(4), 0.5, 0.05)
    assert voxel_map.overlap(np.zeros((0, 3)), np.eye(4), 0.5, 0.05, 1.0) == (0.0, 0.0)


def test_sample_is_seeded_and_bounded_by_the_radius():
    rng = np.random.default_rng(8)
    voxel_map = VoxelMap(1.0, max_points_per_voxel=10)
    voxel_map.update(rng.uniform(-10.0, 10.0, (5000, 3)), np.zeros(3))
    centre = np.array([2.0, 1.0, 0.0])
    a, b = voxel_map.sample(300, centre, 5.0, seed=3), voxel_map.sample(300, centre, 5.0, seed=3)
    np.testing.assert_array_equal(a, b)
    assert len(a) == 300 and np.linalg.norm(a - centre, axis=1).max() <= 5.0
    assert not np.array_equal(a, voxel_map.sample(300, centre, 5.0, seed=4))
    everything = voxel_map.sample(10 ** 6, centre, 5.0)
    assert len(everything) == np.sum(np.linalg.norm(voxel_map.points - centre, axis=1) <= 5.0)
