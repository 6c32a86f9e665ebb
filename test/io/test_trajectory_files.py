"""TUM and KITTI trajectory files: exact stamps, round trips, the format by suffix, the flags CSV."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cemnet_ros.io.trajectory_files import (
    read_kitti,
    read_tum,
    trajectory_format,
    write_columns,
    write_kitti,
    write_trajectory,
    write_tum,
)

STAMPS = [1_700_000_000_000_000_000 + i * 33_333_333 for i in range(12)]


def _poses(n: int, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, :3] = Rotation.from_rotvec(rng.normal(scale=1.0, size=(n, 3))).as_matrix()
    poses[:, :3, 3] = rng.normal(scale=100.0, size=(n, 3))
    return poses


def test_tum_round_trip_keeps_nanosecond_stamps(tmp_path):
    poses = _poses(12)
    path = write_tum(tmp_path / "sub" / "traj.txt", STAMPS, poses)
    lines = [ln for ln in path.read_text().splitlines() if not ln.startswith("#")]
    assert len(lines) == 12 and len(lines[0].split()) == 8
    assert lines[1].split()[0] == "1700000000.033333333"
    q = np.array(lines[3].split()[4:], dtype=float)  # qx qy qz qw: the rotation of pose 3, unit norm
    np.testing.assert_allclose(Rotation.from_quat(q).as_matrix(), poses[3, :3, :3], atol=1e-8)
    stamps_back, poses_back = read_tum(path)
    assert stamps_back.tolist() == STAMPS
    np.testing.assert_allclose(poses_back, poses, atol=1e-8)
    assert not list(path.parent.glob("*.tmp"))  # atomic write leaves no temporary behind


def test_kitti_is_the_3x4_row_major_pose(tmp_path):
    poses = _poses(5)
    path = write_kitti(tmp_path / "poses.kitti", poses)
    table = np.loadtxt(path)
    assert table.shape == (5, 12)
    np.testing.assert_allclose(table.reshape(5, 3, 4), poses[:, :3, :], atol=1e-9)
    np.testing.assert_allclose(read_kitti(path), poses, atol=1e-9)


def test_the_suffix_picks_the_format(tmp_path):
    poses = _poses(3)
    assert [trajectory_format(name) for name in ("a.tum", "a.TXT", "a.kitti")] == ["tum", "tum", "kitti"]
    assert len(write_trajectory(tmp_path / "a.tum", STAMPS[:3], poses).read_text().splitlines()[1].split()) == 8
    assert len(write_trajectory(tmp_path / "a.kitti", STAMPS[:3], poses).read_text().splitlines()[0].split()) == 12
    with pytest.raises(ValueError, match=r"unknown trajectory suffix '.csv'.*\.tum \(TUM\).*\.kitti \(KITTI\)"):
        write_trajectory(tmp_path / "a.csv", STAMPS[:3], poses)
    assert not (tmp_path / "a.csv").exists()


def test_bad_input_is_refused(tmp_path):
    with pytest.raises(ValueError, match="3 stamps but 2 poses"):
        write_tum(tmp_path / "a.tum", STAMPS[:3], _poses(2))
    with pytest.raises(ValueError, match=">= 0"):
        write_tum(tmp_path / "a.tum", [-1], _poses(1))
    nan = _poses(1)
    nan[0, 0, 3] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        write_kitti(tmp_path / "a.kitti", nan)
    (tmp_path / "bad.tum").write_text("0.0 1 2 3 0 0 0\n")
    with pytest.raises(ValueError, match="8 columns"):
        read_tum(tmp_path / "bad.tum")
    (tmp_path / "bad.kitti").write_text("1 0 0 0 0 1 0 0 0 0 1\n")
    with pytest.raises(ValueError, match=":1: expected 12 numbers, got 11"):
        read_kitti(tmp_path / "bad.kitti")


def test_an_empty_trajectory_writes_empty_files(tmp_path):
    assert read_tum(write_tum(tmp_path / "e.tum", [], []))[1].shape == (0, 4, 4)
    assert read_kitti(write_kitti(tmp_path / "e.kitti", [])).shape == (0, 4, 4)


def test_columns_csv_joins_the_tum_file_on_the_stamp(tmp_path):
    accepted = np.array([True, False, True])
    path = write_columns(tmp_path / "f.csv", STAMPS[:3], {"accepted": accepted, "fitness": np.array([0.5, 0.25, 1.0])})
    assert path.read_text().splitlines() == ["stamp,accepted,fitness", "1700000000.000000000,1,0.5",
                                             "1700000000.033333333,0,0.25", "1700000000.066666666,1,1.0"]
    tum = write_tum(tmp_path / "t.tum", STAMPS[:3], _poses(3)).read_text().splitlines()[1:]
    assert [line.split()[0] for line in tum] == [line.split(",")[0] for line in path.read_text().splitlines()[1:]]
    with pytest.raises(ValueError, match="one value per stamp"):
        write_columns(tmp_path / "g.csv", STAMPS[:2], {"accepted": accepted})
