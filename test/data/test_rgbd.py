"""Depth frames to clouds (cemnet_ros.data.rgbd) on small synthetic depth images of planes."""
import numpy as np
import pytest
from depth_images import POSES, SHAPE, WALL_NORMAL, WALL_OFFSET, K, plane_depth_mm, write_folder
from PIL import Image

from cemnet_ros.data import rgbd
from cemnet_ros.data.rgbd import Intrinsics, depth_frames, depth_to_points, read_depth_png, read_intrinsics


def test_back_projection_lands_on_the_plane(tmp_path):
    depth = plane_depth_mm(WALL_NORMAL, WALL_OFFSET, POSES[0])
    path = tmp_path / "d.png"
    Image.fromarray(depth).save(path)
    metres = read_depth_png(path)
    np.testing.assert_allclose(metres, depth / 1000.0)
    points = depth_to_points(metres, K)
    assert points.shape == (SHAPE[0] * SHAPE[1], 3)
    assert np.abs(points @ WALL_NORMAL - WALL_OFFSET).max() < 1e-3  # the mm rounding only
    # the principal point's ray is the optical axis: x = y = 0 there
    centre = depth_to_points(metres[29:30, 40:41], Intrinsics(K.fx, K.fy, 0.0, 0.0))
    np.testing.assert_allclose(centre[0], [0.0, 0.0, depth[29, 40] / 1000.0])
    # x grows to the right (u), y downwards (v)
    assert points[1, 0] > points[0, 0] and points[SHAPE[1], 1] > points[0, 1]


def test_invalid_pixels_stride_and_max_depth(tmp_path):
    depth = plane_depth_mm(WALL_NORMAL, WALL_OFFSET, POSES[0])
    depth[0, :10], depth[1, :5] = 0, 65535
    Image.fromarray(depth).save(tmp_path / "d.png")
    metres = read_depth_png(tmp_path / "d.png")
    assert (metres == 0).sum() == 15
    assert len(depth_to_points(metres, K)) == SHAPE[0] * SHAPE[1] - 15
    assert len(depth_to_points(metres, K, stride=2)) == (SHAPE[0] // 2) * (SHAPE[1] // 2) - 5
    near = depth_to_points(metres, K, max_depth=2.5)
    assert 0 < len(near) < SHAPE[0] * SHAPE[1] - 15 and near[:, 2].max() <= 2.5
    with pytest.raises(ValueError, match="stride"):
        depth_to_points(metres, K, stride=0)
    Image.fromarray(np.zeros(SHAPE, dtype=np.uint8)).save(tmp_path / "eight.png")
    with pytest.raises(ValueError, match="16-bit"):
        read_depth_png(tmp_path / "eight.png")


def test_folder_intrinsics_poses_and_voxel_filter(tmp_path):
    depths = [plane_depth_mm(WALL_NORMAL, WALL_OFFSET, pose) for pose in POSES]
    write_folder(tmp_path, depths, POSES)
    assert read_intrinsics(tmp_path) == K
    assert read_intrinsics(tmp_path / "elsewhere") == rgbd.KINECT_7SCENES
    frames = list(depth_frames(tmp_path))
    assert [f.name for f in frames] == ["frame-000000", "frame-000001"]
    np.testing.assert_allclose(frames[1].T_world_camera, POSES[1])
    (points0, pose0), _ = list(rgbd.rgbd_frames(tmp_path, stride=1, voxel=0.2, max_depth=10.0))
    assert 10 < len(points0) < SHAPE[0] * SHAPE[1] / 8  # one centroid per 20 cm voxel (~4 cm pixels)
    assert np.abs(points0 @ WALL_NORMAL - WALL_OFFSET).max() < 2e-3  # centroids of a plane stay on it
    with pytest.raises(FileNotFoundError):
        list(depth_frames(tmp_path / "none"))
