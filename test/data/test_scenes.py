"""Ray-cast scenes (cemnet_ros.data.scenes), the KITTI loader and the shared-data locator."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from benchmarks.shared import shared_dir
from cemnet_ros.data import scenes
from cemnet_ros.data.kitti import kitti_scans


def _corridor_world_points(x: float, lidar: scenes.LidarModel, seed: int = 0) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, 3] = x, 0.0, 1.5
    scan = scenes.lidar_scan(scenes.corridor_scene(), pose, lidar, np.random.default_rng(seed))
    return scan @ pose[:3, :3].T + pose[:3, 3]


def test_corridor_scan_hits_walls_floor_ceiling_and_nothing_beyond():
    lidar = scenes.LidarModel(n_beams=16, n_azimuth=360)  # max range 100 m: past the open ends at +-60 m
    world = _corridor_world_points(0.0, lidar)
    tol = 0.05  # > 3 sigma of the 1 cm range noise
    assert np.all(np.abs(world[:, 1]) <= 1.5 + tol)
    assert np.all((world[:, 2] >= -tol) & (world[:, 2] <= 3.0 + tol))
    assert np.all(np.abs(world[:, 0]) <= 60.0 + tol)
    surfaces = {"floor": np.abs(world[:, 2]) < tol, "ceiling": np.abs(world[:, 2] - 3.0) < tol,
                "left": np.abs(world[:, 1] - 1.5) < tol, "right": np.abs(world[:, 1] + 1.5) < tol}
    for name, on in surfaces.items():
        assert on.sum() > 200, name
    assert np.all(np.logical_or.reduce(list(surfaces.values())))  # every point lies on one of the four


def test_corridor_is_the_same_everywhere_along_its_axis():
    """Within a range short of the open ends, the scan does not depend on the sensor's x: x is unobservable."""
    lidar = scenes.LidarModel(n_beams=16, n_azimuth=360, max_range=40.0)
    a = _corridor_world_points(0.0, lidar)
    b = _corridor_world_points(7.0, lidar) - [7.0, 0.0, 0.0]
    np.testing.assert_allclose(a, b, atol=1e-4)


def test_courtyard_scan_is_deterministic_for_a_seed():
    scene, lidar = scenes.courtyard_scene(), scenes.LidarModel(n_beams=16, n_azimuth=360)
    pose = scenes.synthetic_trajectory(3)[2]
    a = scenes.lidar_scan(scene, pose, lidar, np.random.default_rng(5))
    b = scenes.lidar_scan(scene, pose, lidar, np.random.default_rng(5))
    c = scenes.lidar_scan(scene, pose, lidar, np.random.default_rng(6))
    np.testing.assert_array_equal(a, b)
    assert a.dtype == np.float32 and a.shape == c.shape and not np.array_equal(a, c)


def test_random_sensor_pose_in_free_space_with_plentiful_points():
    scene, lidar = scenes.courtyard_scene(), scenes.LidarModel(n_beams=16, n_azimuth=360)
    rng = np.random.default_rng(0)
    x_min, x_max, y_min, y_max = scenes.COURTYARD_BOUNDS
    for _ in range(5):
        pose = scenes.random_sensor_pose(scenes.COURTYARD_BOUNDS, rng, scene)
        x, y, z = pose[:3, 3]
        assert x_min <= x <= x_max and y_min <= y <= y_max and abs(z - 1.8) <= 0.1
        assert not scenes.inside_obstacle(scene, pose[:3, 3], margin=1.0)
        np.testing.assert_allclose(pose[:3, :3] @ pose[:3, :3].T, np.eye(3), atol=1e-12)
        assert abs(np.degrees(np.arcsin(pose[2, 0]))) <= 1.0 + 1e-9  # pitch within +-1 deg
        assert len(scenes.lidar_scan(scene, pose, lidar, rng)) > 0.8 * 16 * 360


def test_inside_obstacle_one_point_and_many():
    scene = scenes.courtyard_scene()
    crate, free = [6.0, -6.0, 0.6], [40.0, 0.0, 1.8]
    assert scenes.inside_obstacle(scene, crate) is True
    assert scenes.inside_obstacle(scene, free) is False
    near_pole = [4.0, 4.3, 1.0]  # 0.3 m from the axis of the pole at (4, 4), radius 0.2
    assert not scenes.inside_obstacle(scene, near_pole) and scenes.inside_obstacle(scene, near_pole, margin=0.2)
    np.testing.assert_array_equal(scenes.inside_obstacle(scene, np.array([crate, free])), [True, False])


def test_kitti_scans_full_resolution_and_velodyne_ground_truth(tmp_path: Path):
    tr = np.eye(4)
    tr[:3, :3] = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]  # velodyne -> camera axes
    tr[:3, 3] = [0.1, -0.2, 0.3]
    cam = [np.eye(4), np.eye(4)]
    cam[1][:3, 3] = [0.0, 0.0, 1.5]  # the camera moves 1.5 m along its z (forward)
    (tmp_path / "calib.txt").write_text("P0: 1 0 0 0 0 1 0 0 0 0 1 0\nTr: " + " ".join(map(str, tr[:3].ravel())) + "\n")
    (tmp_path / "poses.txt").write_text("".join(" ".join(map(str, p[:3].ravel())) + "\n" for p in cam))
    (tmp_path / "velodyne").mkdir()
    clouds = [np.random.default_rng(i).normal(size=(1000, 4)).astype(np.float32) for i in range(2)]
    for i, cloud in enumerate(clouds):
        cloud.tofile(tmp_path / "velodyne" / f"{i:06d}.bin")
    frames = list(kitti_scans(tmp_path))
    assert len(frames) == 2
    np.testing.assert_array_equal(frames[0][0], clouds[0][:, :3])
    np.testing.assert_allclose(frames[0][1], np.eye(4), atol=1e-12)
    np.testing.assert_allclose(frames[1][1][:3, 3], [1.5, 0.0, 0.0], atol=1e-12)  # forward = velodyne x


def test_shared_dir_is_the_repository_sibling_or_none():
    found = shared_dir()
    assert found is None or (found.is_dir() and found == Path(__file__).resolve().parents[2].parent / "shared")
