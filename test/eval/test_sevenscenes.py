"""The 7-Scenes clouds of the paper's indoor protocol (cemnet_ros.eval.sevenscenes), cemnet-eval --source rgbd
and scripts/sevenscenes_table.py: on synthetic depth images of planes, and on the real frames (../shared)."""
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from depth_images import (
    POSES,
    SEVENSCENES,
    SHAPE,
    WALL_NORMAL,
    WALL_OFFSET,
    K,
    camera_pose,
    plane_depth_mm,
    write_folder,
)
from scipy.spatial import cKDTree
from shared_data import OFFICIAL_DIR, requires_shared

from cemnet_ros.data.rgbd import depth_frames, depth_to_points, read_intrinsics
from cemnet_ros.eval.protocol import ProtocolConfig, protocol_pairs
from cemnet_ros.eval.sevenscenes import SevenScenesConfig, fused_points, on_unit_cube, resample, sevenscenes_clouds

TABLE_SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "sevenscenes_table.py"


def test_fusion_uses_camera_to_world_poses(tmp_path):
    depths = [plane_depth_mm(WALL_NORMAL, WALL_OFFSET, pose) for pose in POSES]
    write_folder(tmp_path, depths, POSES)
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
    poses = POSES + [camera_pose([0.0, 0.1, 0.0], [0.1, 0.0, 0.0])]
    write_folder(tmp_path, [plane_depth_mm(WALL_NORMAL, WALL_OFFSET, p) for p in poses], poses)
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

    corner = [plane_depth_mm(WALL_NORMAL, WALL_OFFSET, POSES[0]), plane_depth_mm(WALL_NORMAL, 2.0, POSES[1])]
    write_folder(tmp_path / "frames", corner, POSES)
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
    spec = importlib.util.spec_from_file_location("sevenscenes_table", TABLE_SCRIPT)
    table_script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(table_script)
    assert table_script.main(["--data", str(SEVENSCENES), "--official-dir", str(OFFICIAL_DIR), "--seeds", "0,7",
                              "--limit", "2", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert printed == (tmp_path / "sevenscenes.md").read_text() + "\n"
    assert "| 2 (7) | CEMNet, package default weights |" in printed and "| all 2 seeds | ICP" in printed
    results = json.loads((tmp_path / "sevenscenes.json").read_text())
    assert set(results) == {"0", "7"}
    assert {"cemnet", "cemnet_batchnorm", "cemnet_package", "icp"} <= set(results["0"])
    assert len(results["7"]["icp"]["rot_err_deg"]) == 2
