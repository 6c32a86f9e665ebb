"""Depth frames to clouds (data/rgbd.py) and the 7-Scenes clouds of the indoor protocol (eval/sevenscenes.py),
on small synthetic depth images of planes whose geometry is known."""
import json

import numpy as np
import pytest
from PIL import Image
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation
from script_loader import load_script
from shared_data import OFFICIAL_DIR, SHARED, requires_shared

from cemnet_ros.data import rgbd
from cemnet_ros.data.rgbd import Intrinsics, depth_frames, depth_to_points, read_depth_png, read_intrinsics
from cemnet_ros.eval.protocol import ProtocolConfig, protocol_pairs
from cemnet_ros.eval.sevenscenes import SevenScenesConfig, fused_points, on_unit_cube, resample, sevenscenes_clouds

K = Intrinsics(60.0, 55.0, 40.5, 29.5)  # an 80 x 60 image, fx != fy so that a swap would show
SHAPE = (60, 80)
SEVENSCENES = SHARED / "data" / "rgbd_7scenes"


def _pose(rotvec, translation) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    pose[:3, 3] = translation
    return pose


def _plane_depth_mm(normal, offset, T_world_camera) -> np.ndarray:
    """Depth (uint16 mm) of the world plane ``normal . p = offset`` seen by a camera at ``T_world_camera``."""
    R, t = T_world_camera[:3, :3], T_world_camera[:3, 3]
    v, u = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    rays = np.stack([(u - K.cx) / K.fx, (v - K.cy) / K.fy, np.ones(SHAPE)], axis=-1)  # z = 1 per ray
    z = (offset - normal @ t) / (rays @ R.T @ normal)  # p_world = R (z ray) + t on the plane
    return np.round(z * 1000.0).astype(np.uint16)


def _write_folder(root, depths, poses) -> None:
    (root / "rgbd-frames").mkdir(parents=True)
    np.savetxt(root / "camera-intrinsics.txt", [[K.fx, 0, K.cx], [0, K.fy, K.cy], [0, 0, 1]])
    for i, (depth, pose) in enumerate(zip(depths, poses)):
        Image.fromarray(depth).save(root / "rgbd-frames" / f"frame-{i:06d}.depth.png")
        np.savetxt(root / "rgbd-frames" / f"frame-{i:06d}.pose.txt", pose)


WALL_NORMAL, WALL_OFFSET = np.array([0.2, -0.1, 1.0]) / np.linalg.norm([0.2, -0.1, 1.0]), 2.5
POSES = [_pose([0.0, 0.0, 0.0], [0.0, 0.0, 0.0]), _pose([0.05, -0.1, 0.02], [0.3, -0.1, 0.2])]


def test_back_projection_lands_on_the_plane(tmp_path):
    depth = _plane_depth_mm(WALL_NORMAL, WALL_OFFSET, POSES[0])
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
    depth = _plane_depth_mm(WALL_NORMAL, WALL_OFFSET, POSES[0])
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
    depths = [_plane_depth_mm(WALL_NORMAL, WALL_OFFSET, pose) for pose in POSES]
    _write_folder(tmp_path, depths, POSES)
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


def test_fusion_uses_camera_to_world_poses(tmp_path):
    depths = [_plane_depth_mm(WALL_NORMAL, WALL_OFFSET, pose) for pose in POSES]
    _write_folder(tmp_path, depths, POSES)
    frames = list(depth_frames(tmp_path))
    fused = fused_points(frames, K, SevenScenesConfig(voxel=0.0))
    assert len(fused) == 2 * SHAPE[0] * SHAPE[1]
    # the second frame's points, moved into the first camera's frame, lie on the same plane
    assert np.abs(fused @ WALL_NORMAL - WALL_OFFSET).max() < 2e-3
    second_alone = depth_to_points(frames[1].depth_m, K)
    assert np.abs(second_alone @ WALL_NORMAL - WALL_OFFSET).mean() > 0.05  # ... which they did not before


def test_unit_cube_and_resampling():
    rng = np.random.default_rng(0)
    points = rng.uniform([-1, 0, 2], [3, 1, 2.5], size=(500, 3))
    cube = on_unit_cube(points)
    np.testing.assert_allclose((cube.max(0) - cube.min(0)).max(), 1.0)
    np.testing.assert_allclose(cube.mean(0), 0.0, atol=1e-12)
    extent = (points.max(0) - points.min(0)).max()  # ~4, along x
    np.testing.assert_allclose(cube * extent + points.mean(0), points)  # a scale and a shift only
    fewer = resample(cube, 300, np.random.default_rng(1))
    assert len(np.unique(fewer, axis=0)) == 300
    more = resample(cube, 1200, np.random.default_rng(1))
    counts = np.unique(more, axis=0, return_counts=True)[1]
    assert len(counts) == 500 and set(counts) == {2, 3}  # every point used before any repeats
    with pytest.raises(ValueError, match="coincide"):
        on_unit_cube(np.ones((5, 3)))


def test_sevenscenes_clouds_windows_and_seeds(tmp_path):
    poses = POSES + [_pose([0.0, 0.1, 0.0], [0.1, 0.0, 0.0])]
    _write_folder(tmp_path, [_plane_depth_mm(WALL_NORMAL, WALL_OFFSET, p) for p in poses], poses)
    points, names = sevenscenes_clouds(tmp_path, SevenScenesConfig(voxel=0.0, n_resample=256))
    assert points.shape == (3, 256, 3) and points.dtype == np.float32
    assert names == ["frame-000000", "frame-000001", "frame-000002"]
    extents = (points.max(1) - points.min(1)).max(1)  # 256 of the cloud's points: inside its unit cube
    assert np.all((extents > 0.9) & (extents <= 1.0 + 1e-6))
    again, _ = sevenscenes_clouds(tmp_path, SevenScenesConfig(voxel=0.0, n_resample=256))
    np.testing.assert_array_equal(points, again)
    other, _ = sevenscenes_clouds(tmp_path, SevenScenesConfig(voxel=0.0, n_resample=256, seed=5))
    assert not np.array_equal(points, other)
    fused, fused_names = sevenscenes_clouds(tmp_path, SevenScenesConfig(frames_per_cloud=2, n_resample=256))
    assert fused.shape == (1, 256, 3) and fused_names == ["frame-000000..frame-000001"]
    with pytest.raises(ValueError, match="fewer than frames_per_cloud"):
        sevenscenes_clouds(tmp_path, SevenScenesConfig(frames_per_cloud=4))


def test_eval_cli_on_rgbd_frames(tmp_path, capsys):
    from cemnet_ros.tools import eval_cli

    corner = [_plane_depth_mm(WALL_NORMAL, WALL_OFFSET, POSES[0]), _plane_depth_mm(WALL_NORMAL, 2.0, POSES[1])]
    _write_folder(tmp_path / "frames", corner, POSES)
    out = tmp_path / "r.json"
    assert eval_cli.main(["--source", "rgbd", "--data", str(tmp_path / "frames"), "--methods", "icp",
                          "--rgbd.voxel", "0", "--out-json", str(out)]) == 0
    assert "7-Scenes frames (1 per cloud), 2 pairs" in capsys.readouterr().out
    report = json.loads(out.read_text())
    assert [p["label"] for p in report["per_pair"]["icp"]] == ["frame-000000", "frame-000001"]
    assert report["config"]["rgbd"]["voxel"] == 0.0 and report["config"]["protocol"]["n_partial"] == 768
    assert eval_cli.main(["--source", "rgbd", "--data", str(tmp_path / "frames"), "--setting", "unseen",
                          "--methods", "icp"]) == 2
    assert "unseen" in capsys.readouterr().err
    assert eval_cli.main(["--source", "rgbd", "--data", str(tmp_path / "none"), "--methods", "icp"]) == 2
    assert "not found" in capsys.readouterr().err


@requires_shared(SEVENSCENES)
def test_real_frames_fuse_with_their_poses():
    frames = list(depth_frames(SEVENSCENES))
    assert len(frames) == 50 and frames[0].name == "frame-000008"
    intrinsics = read_intrinsics(SEVENSCENES)
    first, last = frames[0], frames[-1]  # 5 deg and 25 cm apart
    first_points = cKDTree(depth_to_points(first.depth_m, intrinsics, stride=2))
    last_points = depth_to_points(last.depth_m, intrinsics, stride=2)
    moved = fused_points([first, last], intrinsics, SevenScenesConfig(stride=2, voxel=0.0))[first_points.n:]
    assert np.median(first_points.query(moved)[0]) < 0.015  # the last frame lands on the first within ~1 cm
    T_last_first = np.linalg.inv(last.T_world_camera) @ first.T_world_camera  # the pose read the wrong way
    wrong = last_points @ T_last_first[:3, :3].T + T_last_first[:3, 3]
    assert np.median(first_points.query(wrong)[0]) > 0.1
    assert np.median(first_points.query(last_points)[0]) > 0.05  # and not fused at all


@requires_shared(SEVENSCENES)
def test_real_sevenscenes_pairs():
    points, names = sevenscenes_clouds(SEVENSCENES, SevenScenesConfig())
    assert points.shape == (50, 2048, 3) and names[0] == "frame-000008" and names[-1] == "frame-000057"
    extents = points.max(1) - points.min(1)
    assert np.all(extents.max(1) <= 1.0 + 1e-6) and np.all(extents.max(1) > 0.9)
    for pair in protocol_pairs(points[:10], ProtocolConfig()):
        assert pair.source.shape == pair.target.shape == (768, 3)
        moved = pair.source.astype(np.float64) @ pair.rotation.T + pair.translation
        # the two crops overlap: most moved source points have a target point nearby
        assert np.mean(cKDTree(pair.target).query(moved)[0] < 0.02) > 0.5


@pytest.mark.slow
@requires_shared(OFFICIAL_DIR)
@requires_shared(SEVENSCENES)
def test_sevenscenes_table_script(tmp_path, capsys):
    table_script = load_script("sevenscenes_table")
    assert table_script.main(["--data", str(SEVENSCENES), "--official-dir", str(OFFICIAL_DIR), "--seeds", "0,7",
                              "--limit", "2", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert printed == (tmp_path / "sevenscenes.md").read_text() + "\n"
    assert "| 2 (7) | CEMNet, package default weights |" in printed and "| all 2 seeds | ICP" in printed
    results = json.loads((tmp_path / "sevenscenes.json").read_text())
    assert set(results) == {"0", "7"}
    assert {"cemnet", "cemnet_batchnorm", "cemnet_package", "icp"} <= set(results["0"])
    assert len(results["7"]["icp"]["rot_err_deg"]) == 2
