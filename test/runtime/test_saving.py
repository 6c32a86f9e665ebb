"""~/save_map and ~/save_trajectory as plain code: where the files go, their formats, and failures as one line."""
from __future__ import annotations

import os
import time
from types import SimpleNamespace

import numpy as np
import pytest

from cemnet_ros.io.pointcloud_files import read_points
from cemnet_ros.io.trajectory_files import read_kitti, read_tum
from cemnet_ros.runtime.saving import flags_path, save_directory, save_map, save_path, save_trajectory
from cemnet_ros.runtime.trajectory_log import TrajectoryLog

POINTS = np.random.default_rng(1).normal(scale=10.0, size=(200, 3))
NOON = time.strptime("2026-01-02 12:30:05", "%Y-%m-%d %H:%M:%S")


def _trajectory(n=5, max_poses=1000):
    log = TrajectoryLog(max_poses)
    for k in range(n):
        T = np.eye(4)
        T[:3, 3] = [0.5 * k, 0.1 * k, 0.0]
        log.append(1_000_000_000 + k * 100_000_001, T, SimpleNamespace(accepted=k != 2, degenerate=False,
                                                                         recovered=k == 0, fitness=0.5 + k / 10))
    return log.snapshot()


def test_paths_expand_time_home_and_the_save_directory(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert save_path("map_{time}.pcd", str(tmp_path), NOON) == tmp_path / "map_20260102_123005.pcd"
    assert save_path("/abs/run.ply", str(tmp_path)).as_posix() == "/abs/run.ply"
    assert save_path("~/maps/a.pcd", str(tmp_path)) == tmp_path / "home" / "maps" / "a.pcd"
    assert save_directory("", {"ROS_HOME": str(tmp_path / "ros")}) == tmp_path / "ros" / "cemnet_ros"
    assert save_directory("", {}) == tmp_path / "home" / ".ros" / "cemnet_ros"
    assert save_directory("~/out", {}) == tmp_path / "home" / "out"
    monkeypatch.chdir(tmp_path)
    assert save_path("m.pcd", "rel") == tmp_path / "rel" / "m.pcd"  # a relative folder: the working directory's


@pytest.mark.parametrize("name, header", [("map.pcd", b"# .PCD v0.7"), ("maps/new/map.PLY", b"ply\n")])
def test_the_map_is_written_in_the_suffix_s_format_in_a_created_folder(tmp_path, name, header):
    saved = save_map(POINTS, name, str(tmp_path), "odom")
    path = tmp_path / name
    assert saved.success and saved.message == f"wrote 200 map points (odom) to {path}"
    assert path.read_bytes().startswith(header)
    np.testing.assert_array_equal(read_points(path), POINTS.astype(np.float32))


def test_map_failures_are_one_line_and_write_nothing(tmp_path):
    assert save_map(None, "map.pcd", str(tmp_path), "odom").message == "no map yet: no scan has been registered"
    saved = save_map(POINTS, "map.xyz", str(tmp_path), "odom")
    assert not saved.success and "unknown map suffix '.xyz'" in saved.message and "use .pcd" in saved.message
    (tmp_path / "file").write_text("a file, not a folder")
    for name in ("file/map.pcd", "file/sub/map.pcd"):
        saved = save_map(POINTS, name, str(tmp_path), "odom")
        blocked = f"{tmp_path}/file is a file, not a folder"
        assert saved.message == f"map not saved: cannot write {tmp_path / name}: {blocked}"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]
    assert not save_map(POINTS, "  ", str(tmp_path), "odom").success


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_permission_denied_is_said(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    saved = save_map(POINTS, "map.pcd", str(locked), "odom")
    assert not saved.success and saved.message == f"map not saved: cannot write {locked}/map.pcd: permission denied"


def test_the_trajectory_as_tum_and_kitti_with_its_flags(tmp_path):
    trajectory = _trajectory()
    saved = save_trajectory(trajectory, "run_{time}.tum", str(tmp_path), "odom", "base_link")
    (path,) = tmp_path.glob("run_*.tum")
    assert saved.success and saved.message.startswith(f"wrote 5 poses of base_link in odom (1 flagged) as TUM to "
                                                      f"{path}, their flags to {flags_path(path)}")
    stamps, poses = read_tum(path)
    assert stamps.tolist() == trajectory.stamps_ns.tolist()
    np.testing.assert_allclose(poses, trajectory.poses, atol=1e-9)
    rows = flags_path(path).read_text().splitlines()
    assert rows[0] == "stamp,accepted,degenerate,recovered,fitness"
    assert rows[3] == "1.200000002,0,0,0,0.7" and rows[1].split(",")[1:4] == ["1", "0", "1"]
    saved = save_trajectory(trajectory, "run.kitti", str(tmp_path), "odom", "base_link")
    assert saved.success and " as KITTI to " in saved.message
    np.testing.assert_allclose(read_kitti(tmp_path / "run.kitti"), trajectory.poses, atol=1e-9)
    assert (tmp_path / "run.flags.csv").read_text().splitlines() == rows  # the KITTI rows' stamps


def test_trajectory_failures_and_the_dropped_poses_are_said(tmp_path):
    empty = TrajectoryLog(10).snapshot()
    assert save_trajectory(empty, "a.tum", str(tmp_path), "odom", "base").message == \
        "no trajectory yet: no scan has been processed"
    saved = save_trajectory(_trajectory(), "a.csv", str(tmp_path), "odom", "base")
    assert not saved.success and "unknown trajectory suffix '.csv'" in saved.message
    assert not list(tmp_path.iterdir())
    saved = save_trajectory(_trajectory(n=5, max_poses=3), "a.tum", str(tmp_path), "odom", "base")
    assert saved.success and saved.message.endswith("the 2 oldest poses were dropped before (trajectory_max_poses)")
    assert len(read_tum(tmp_path / "a.tum")[0]) == 3
