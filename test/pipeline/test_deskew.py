"""Deskewing: the constant-velocity correction, the time-field conventions, their PointCloud2 decoding, the
skewed synthetic sequence and the aligner on it (deskew on beats off)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from scipy.linalg import expm
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import PointCloud2, PointField

from cemnet_ros.core.geometry import se3_log
from cemnet_ros.data.scenes import LidarModel
from cemnet_ros.data.skewed import circle_poses, skewed_sequence
from cemnet_ros.pipeline.steps.deskew import deskew
from cemnet_ros.point_times import TimeFieldError, normalize_point_times
from cemnet_ros.pointcloud2 import CloudError, decode_point_times, decode_xyz

STAMP_NS = 1_700_000_000_123_456_789  # an epoch stamp: absolute times are ~1.7e9 s


def _hat(xi: np.ndarray) -> np.ndarray:
    """4x4 se(3) matrix of a twist [rho, omega]."""
    rho, w = xi[:3], xi[3:]
    return np.array([[0.0, -w[2], w[1], rho[0]], [w[2], 0.0, -w[0], rho[1]], [-w[1], w[0], 0.0, rho[2]],
                     [0.0, 0.0, 0.0, 0.0]])


@pytest.mark.parametrize("twist", [
    np.array([15.0, 0.4, -0.1, 0.02, -0.03, np.radians(30.0)]),  # a car: 15 m/s, 30 deg/s yaw
    np.array([-2.0, 1.0, 0.5, 1.5, -2.0, 3.0]),  # a tumbling handheld: ~210 deg/s
    np.array([10.0, 0.0, 0.0, 0.0, 0.0, 1e-7]),  # (almost) pure translation: the Taylor branch
])
def test_deskew_is_exact_for_a_constant_velocity(twist):
    rng = np.random.default_rng(0)
    at_stamp = rng.normal(size=(300, 3)) * 20.0
    times = rng.uniform(-0.1, 0.1, 300)
    # Each point as measured at its own time: in the sensor frame at t, T_stamp_t = exp(t xi).
    measured = np.array([(np.linalg.inv(expm(t * _hat(twist))) @ np.r_[p, 1.0])[:3] for p, t in zip(at_stamp, times)])
    dt = 0.1
    T_prev_curr = expm(dt * _hat(twist))
    np.testing.assert_allclose(se3_log(T_prev_curr) / dt, twist, atol=1e-9)
    np.testing.assert_allclose(deskew(measured, times, T_prev_curr, dt), at_stamp, atol=1e-9, rtol=0)
    # Given the twist itself, the same.
    np.testing.assert_allclose(deskew(measured, times, None, dt, twist=twist), at_stamp, atol=1e-9, rtol=0)


def test_zero_velocity_or_zero_times_is_the_identity():
    rng = np.random.default_rng(1)
    points = rng.normal(size=(50, 3)).astype(np.float32)
    out = deskew(points, rng.uniform(0, 0.1, 50), np.eye(4), 0.1)
    assert out.dtype == np.float64 and out is not points
    np.testing.assert_array_equal(out, points.astype(np.float64))
    T = np.eye(4)
    T[:3, 3] = 1.5
    np.testing.assert_array_equal(deskew(points, np.zeros(50), T, 0.1), points.astype(np.float64))
    with pytest.raises(ValueError):
        deskew(points, np.zeros(49), T, 0.1)
    with pytest.raises(ValueError):
        deskew(points, np.zeros(50), T, 0.0)


OFFSETS = np.linspace(0.0, 0.0999, 7)  # s: a 10 Hz sweep


@pytest.mark.parametrize("name, raw, expected", [
    ("ouster t, uint32 ns from the stamp", (OFFSETS * 1e9).astype(np.uint32), OFFSETS),
    ("livox offset_time, uint32 ns", (OFFSETS * 1e9).astype(np.uint32), OFFSETS),
    ("velodyne time, float32 s before the stamp", (OFFSETS - 0.1).astype(np.float32), OFFSETS - 0.1),
    ("hesai timestamp, float64 absolute s", STAMP_NS * 1e-9 + OFFSETS, OFFSETS),
    ("livox timestamp, float64 absolute ns", STAMP_NS + OFFSETS * 1e9, OFFSETS),
    ("old ouster t, float32 ns from the stamp", (OFFSETS * 1e9).astype(np.float32), OFFSETS),
])
def test_normalize_point_times_reads_each_driver_convention(name, raw, expected):
    times = normalize_point_times(raw, STAMP_NS, name)
    assert times.dtype == np.float64
    tolerance = 1e-6 if raw.dtype == np.float64 and raw.max() > 1e6 else 1e-8  # absolute float64: ~0.2 us
    np.testing.assert_allclose(times, expected, atol=tolerance, rtol=0)


def test_normalize_point_times_sim_time_nonfinite_and_implausible():
    # Absolute seconds under a simulated clock (stamp 100 s): not mistaken for offsets from the stamp.
    np.testing.assert_allclose(normalize_point_times(100.0 + OFFSETS, 100_000_000_000), OFFSETS, atol=1e-9)
    raw = np.array([0.01, np.nan, 0.02, np.inf])
    np.testing.assert_array_equal(normalize_point_times(raw, STAMP_NS), [0.01, 0.0, 0.02, 0.0])
    with pytest.raises(TimeFieldError, match="fits no convention"):
        normalize_point_times(np.array([3.0, 5.0]), STAMP_NS, "time")  # seconds, but 3 s from the stamp
    with pytest.raises(TimeFieldError):
        normalize_point_times(np.array([2_000_000_000], dtype=np.uint32), STAMP_NS)  # 2 s in ns
    with pytest.raises(TimeFieldError, match="dtype"):
        normalize_point_times(np.array(["a"]), STAMP_NS)


_NUMPY = {PointField.UINT32: "u4", PointField.FLOAT32: "f4", PointField.FLOAT64: "f8"}


def _cloud(points: np.ndarray, time_name, time_values, time_type, *, big_endian=False, height=1,
           stamp_ns=STAMP_NS) -> PointCloud2:
    """An rclpy PointCloud2: float32 x y z, a float32 intensity, then the time field (8-byte aligned), padded."""
    end = ">" if big_endian else "<"
    names = [("x", "f4"), ("y", "f4"), ("z", "f4"), ("intensity", "f4")]
    if time_name is not None:
        names.append((time_name, _NUMPY[time_type]))
    dtype = np.dtype({"names": [n for n, _ in names], "formats": [end + f for _, f in names],
                      "offsets": [0, 4, 8, 12, 16][:len(names)], "itemsize": 32})
    rows = np.zeros(len(points), dtype=dtype)
    for axis, n in enumerate("xyz"):
        rows[n] = points[:, axis]
    if time_name is not None:
        rows[time_name] = time_values
    msg = PointCloud2()
    msg.header.stamp = Time(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
    msg.height, msg.width = height, len(points) // height
    fields = [PointField(name=n, offset=o, datatype=PointField.FLOAT32, count=1)
              for n, o in zip(("x", "y", "z", "intensity"), (0, 4, 8, 12))]
    if time_name is not None:
        fields.append(PointField(name=time_name, offset=16, datatype=time_type, count=1))
    msg.fields = fields
    msg.is_bigendian, msg.point_step, msg.row_step = big_endian, 32, 32 * msg.width
    msg.data = rows.tobytes()
    msg.is_dense = False
    return msg


def _points_with_holes(n: int = 12) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(2)
    points = rng.normal(size=(n, 3)) * 10.0
    points[[1, 6], 0] = np.nan  # organised-cloud holes: decode_xyz drops these rows
    points[9, 2] = np.inf
    return points, np.isfinite(points).all(axis=1)


@pytest.mark.parametrize("name, time_type, make, big_endian, height", [
    ("t", PointField.UINT32, lambda s: (s * 1e9).astype(np.uint32), False, 1),  # Ouster
    ("time", PointField.FLOAT32, lambda s: (s - 0.1).astype(np.float32), False, 1),  # Velodyne: before the stamp
    ("timestamp", PointField.FLOAT64, lambda s: STAMP_NS * 1e-9 + s, False, 1),  # Hesai: absolute s
    ("timestamp", PointField.FLOAT64, lambda s: STAMP_NS + s * 1e9, True, 2),  # Livox: absolute ns, organised
    ("offset_time", PointField.UINT32, lambda s: (s * 1e9).astype(np.uint32), True, 3),  # Livox custom
])
def test_decode_point_times_follows_decode_xyz_rows(name, time_type, make, big_endian, height):
    points, finite = _points_with_holes()
    offsets = np.linspace(0.0, 0.099, len(points))
    msg = _cloud(points, name, make(offsets), time_type, big_endian=big_endian, height=height)
    xyz, report = decode_xyz(msg)
    times = decode_point_times(msg)
    assert report.n_nonfinite == 3 and times.dtype == np.float64 and times.shape == (len(xyz),)
    expected = offsets[finite] - (0.1 if name == "time" else 0.0)
    np.testing.assert_allclose(times, expected, atol=1e-6 if time_type == PointField.FLOAT64 else 1e-7, rtol=0)
    np.testing.assert_allclose(xyz, points[finite].astype(np.float32), rtol=1e-6)


def test_decode_point_times_without_a_time_field_or_with_a_bad_one():
    points, _ = _points_with_holes()
    assert decode_point_times(_cloud(points, None, None, None)) is None
    bad = _cloud(points, "time", np.full(len(points), 7.5), PointField.FLOAT32)  # 7.5 s from the stamp
    with pytest.raises(CloudError) as info:
        decode_point_times(bad)
    assert info.value.kind == "time_field"
    # An explicit stamp overrides the header's: absolute seconds against it.
    msg = _cloud(points, "timestamp", np.full(len(points), 50.05), PointField.FLOAT64)
    np.testing.assert_allclose(decode_point_times(msg, stamp_ns=50_000_000_000), 0.05, atol=1e-9)


SMALL_LIDAR = LidarModel(n_beams=16, n_azimuth=240)


def test_skewed_scans_are_taken_along_the_trajectory_and_deskewing_recovers_them():
    lidar = dataclasses.replace(SMALL_LIDAR, range_noise=0.0)
    seq = skewed_sequence(3, seed=4, lidar=lidar, stamp_at=0.5)
    times, points, stamp_pose = seq.times[2], seq.scans[2].astype(np.float64), seq.poses[2]
    assert times.min() == pytest.approx(-0.05) and times.max() < 0.05 and len(times) == len(points)
    # The true pose of each point's own time, from the same trajectory.
    rng = np.random.default_rng(4)
    phase, direction = rng.uniform(0.0, 2 * np.pi), float(rng.choice([-1.0, 1.0]))
    own = circle_poses(0.2 + times, phase, direction)
    world = np.einsum("nij,nj->ni", own[:, :3, :3], points) + own[:, :3, 3]
    T = np.linalg.inv(seq.poses[1]) @ seq.poses[2]
    relative = Rotation.from_matrix(T[:3, :3]).magnitude()
    assert np.linalg.norm(T[:3, 3]) == pytest.approx(1.5, abs=0.01)
    assert np.degrees(relative) == pytest.approx(3.0, abs=0.1)
    as_stamped = points @ stamp_pose[:3, :3].T + stamp_pose[:3, 3]
    fixed = deskew(points, times, T, 0.1) @ stamp_pose[:3, :3].T + stamp_pose[:3, 3]
    skew_error, fixed_error = (np.linalg.norm(w - world, axis=1) for w in (as_stamped, fixed))
    assert np.max(skew_error) > 0.7 and np.max(fixed_error) < 0.01  # float32 points, small oscillations


def test_aligner_with_deskew_beats_without_on_a_skewed_drive():
    from cemnet_ros.pipeline.aligner import AlignerConfig, ScanAligner

    seq = skewed_sequence(10, seed=0, lidar=SMALL_LIDAR)
    config = AlignerConfig()
    errors = {}
    for deskew_on in (False, True):
        aligner = ScanAligner(dataclasses.replace(config, preprocess=dataclasses.replace(config.preprocess,
                                                                                         deskew=deskew_on)))
        poses = [aligner.process(p.astype(np.float64), s, t).pose
                 for p, t, s in zip(seq.scans, seq.times, seq.stamps_ns)]
        assert np.allclose(poses[0], np.eye(4))  # odom: the first scan's sensor frame at its stamp
        truth = [np.linalg.inv(seq.poses[0]) @ g for g in seq.poses]
        errors[deskew_on] = float(np.sqrt(np.mean([np.sum((p[:3, 3] - g[:3, 3]) ** 2) for p, g in zip(poses, truth)])))
    assert errors[True] < 0.5 * errors[False], errors
