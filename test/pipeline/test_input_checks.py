"""The plausibility checks before registration: each refuses what it should and lets the normal stream pass."""
from types import SimpleNamespace

import numpy as np
import pytest

from cemnet_ros.data.scenes import LidarModel, courtyard_scene, raycast, synthetic_trajectory
from cemnet_ros.pipeline.aligner import ScanAligner
from cemnet_ros.pipeline.config import AlignerConfig, InputChecksConfig
from cemnet_ros.pipeline.errors import ScanRejected
from cemnet_ros.pipeline.steps.input_checks import InputChecks, stamp_ns
from cemnet_ros.pointcloud2 import FLOAT32, decode_scan

PERIOD = 100_000_000  # 10 Hz


def _cloud(n, seed=0):
    return np.random.default_rng(seed).normal(size=(n, 3)) * 10.0


def _stream(checks, n_scans=5, n_points=1000, frame="lidar", t0=0):
    for k in range(n_scans):
        stamp = t0 + k * PERIOD
        checks.passed(checks.admit(_cloud(n_points, k), None, stamp, frame))
    return t0 + (n_scans - 1) * PERIOD


def test_a_normal_stream_passes_without_warnings():
    checks = InputChecks(InputChecksConfig())
    last = _stream(checks, 10)
    admitted = checks.admit(_cloud(990), None, last + PERIOD, "lidar")
    assert not admitted.warnings and not admitted.restart and len(admitted.points) == 990


@pytest.mark.parametrize("n", [60, 200, 300])
def test_a_scan_with_a_fraction_of_the_usual_points_is_refused(n):
    checks = InputChecks(InputChecksConfig())
    last = _stream(checks)
    with pytest.raises(ScanRejected) as info:
        checks.admit(_cloud(n), None, last + PERIOD, "lidar")
    assert info.value.kind == "point_count"


@pytest.mark.parametrize("hole", [(np.nan, np.nan, np.nan), (np.inf, np.inf, np.inf), (-np.inf, 1.0, 2.0),
                                  (1.0, 2.0, np.nan)], ids=["nan", "inf", "minus_inf_in_x", "nan_in_z"])
def test_non_finite_points_are_dropped_with_their_times_and_never_refuse_a_scan(hole):
    checks = InputChecks(InputChecksConfig())
    last = _stream(checks)  # no holes so far
    finite = _cloud(1000, seed=7)
    cloud = np.insert(finite, np.arange(0, 1000, 2), hole, axis=0)  # 500 holes: a third of the points
    times = np.arange(len(cloud)) * 1e-4
    admitted = checks.admit(cloud, times, last + PERIOD, "lidar")
    assert not admitted.warnings and admitted.n_finite == 1000
    np.testing.assert_array_equal(admitted.points, finite)
    np.testing.assert_array_equal(admitted.times, times[np.isfinite(cloud).all(axis=1)])


def test_a_share_of_holes_that_jumps_from_none_to_most_passes_while_the_finite_points_meet_the_levels():
    checks = InputChecks(InputChecksConfig())
    last = _stream(checks)
    open_sky = np.full((6000, 3), np.nan)  # 6000 no-returns around 990 returns
    admitted = checks.admit(np.vstack([open_sky, _cloud(990)]), None, last + PERIOD, "lidar")
    assert not admitted.warnings and len(admitted.points) == 990
    checks.passed(admitted)
    with pytest.raises(ScanRejected) as info:  # too few finite points is still refused, holes or not
        checks.admit(np.vstack([open_sky, _cloud(300)]), None, last + 2 * PERIOD, "lidar")
    assert info.value.kind == "point_count"


def test_a_sector_of_a_scan_is_refused_however_many_points_it_has():
    checks = InputChecks(InputChecksConfig())
    last = _stream(checks)
    cloud = _cloud(4000, seed=9)
    sector = cloud[(cloud[:, 0] > 0) & (cloud[:, 1] > 0)]  # 90 degrees: ~1000 points, the usual count
    with pytest.raises(ScanRejected, match="azimuth sectors") as info:
        checks.admit(sector, None, last + PERIOD, "lidar")
    assert info.value.kind == "coverage"


def test_a_lasting_change_of_the_point_count_relevels_with_a_warning():
    config = InputChecksConfig(relevel_after=3)
    checks = InputChecks(config)
    stamp = _stream(checks)
    for _ in range(2):
        stamp += PERIOD
        with pytest.raises(ScanRejected):
            checks.admit(_cloud(300), None, stamp, "lidar")
    stamp += PERIOD
    admitted = checks.admit(_cloud(300), None, stamp, "lidar")
    assert [kind for kind, _ in admitted.warnings] == ["relevel"]
    checks.passed(admitted)
    checks.admit(_cloud(300), None, stamp + PERIOD, "lidar")  # the new level holds


def test_another_frame_is_refused_until_a_reset():
    checks = InputChecks(InputChecksConfig())
    last = _stream(checks)
    with pytest.raises(ScanRejected) as info:
        checks.admit(_cloud(1000), None, last + PERIOD, "robot2/velodyne")
    assert info.value.kind == "frame_id"
    checks.forget_frame()
    checks.admit(_cloud(1000), None, last + PERIOD, "robot2/velodyne")


def test_stamps_ahead_of_the_clock_or_with_bad_nanoseconds_are_refused():
    checks = InputChecks(InputChecksConfig(future_tolerance=2.0))
    last = _stream(checks)
    with pytest.raises(ScanRejected) as info:
        checks.admit(_cloud(1000), None, (2 ** 31 - 1) * 1_000_000_000, "lidar", now_ns=last + PERIOD)
    assert info.value.kind == "stamp_future" and "clock reads 0" not in str(info.value)
    with pytest.raises(ScanRejected) as info:  # ROS time unset: use_sim_time before the first /clock
        InputChecks(InputChecksConfig()).admit(_cloud(1000), None, 1_700_000_000 * 10 ** 9, "lidar", now_ns=0)
    assert info.value.kind == "stamp_future" and "clock reads 0" in str(info.value) and "/clock" in str(info.value)
    with pytest.raises(ScanRejected) as info:
        stamp_ns(5, 2 ** 32 - 1)
    assert info.value.kind == "stamp"
    assert stamp_ns(5, 7) == 5_000_000_007


def test_a_stamp_jump_is_refused_unless_the_next_scan_confirms_it():
    checks = InputChecks(InputChecksConfig(stamp_jump=30.0))
    last = _stream(checks)
    corrupt = (2 ** 31 - 1) * 1_000_000_000
    with pytest.raises(ScanRejected) as info:
        checks.admit(_cloud(1000), None, corrupt, "lidar")
    assert info.value.kind == "stamp_jump"
    checks.admit(_cloud(1000), None, last + PERIOD, "lidar")  # the stream goes on unaffected
    jumped = last + 3600 * 1_000_000_000
    with pytest.raises(ScanRejected):
        checks.admit(_cloud(1000), None, jumped, "lidar")
    checks.admit(_cloud(1000), None, jumped + PERIOD, "lidar")  # confirmed: a new time base


def test_a_trajectory_that_began_on_a_tiny_scan_restarts_from_the_first_representative_one():
    checks = InputChecks(InputChecksConfig())
    tiny = checks.admit(_cloud(60), None, 0, "lidar")
    checks.passed(tiny)
    admitted = checks.admit(_cloud(5000), None, PERIOD, "lidar")
    assert admitted.restart and admitted.warnings[0][0] == "implausible_start"
    checks.passed(admitted)
    with pytest.raises(ScanRejected):  # the level is now the representative scan's
        checks.admit(_cloud(60), None, 2 * PERIOD, "lidar")


def test_a_huge_cloud_is_decimated_with_its_times_and_a_warning():
    checks = InputChecks(InputChecksConfig(max_points=1000))
    cloud, times = _cloud(5000), np.linspace(0.0, 0.1, 5000)
    admitted = checks.admit(cloud, times, 0, "lidar")
    assert len(admitted.points) == 1000 and len(admitted.times) == 1000
    assert admitted.warnings[0][0] == "decimated"
    index = np.searchsorted(times, admitted.times)
    assert np.array_equal(cloud[index], admitted.points)  # points and times stay paired


def test_an_out_of_order_stamp_is_refused_and_a_confirmed_step_back_passes():
    checks = InputChecks(InputChecksConfig())
    last = _stream(checks)
    with pytest.raises(ScanRejected) as info:
        checks.admit(_cloud(1000), None, last - PERIOD // 2, "lidar")
    assert info.value.kind == "stamp_back"
    checks.admit(_cloud(1000), None, last + PERIOD, "lidar")  # the stream goes on
    with pytest.raises(ScanRejected):
        checks.admit(_cloud(1000), None, 0, "lidar")  # a bag loop ...
    checks.admit(_cloud(1000), None, PERIOD, "lidar")  # ... confirmed by the next scan


# -- organised clouds through the aligner: a holed scan after clean ones aligns as its finite points do --------

OS0 = LidarModel(n_beams=64, n_azimuth=180, elevation_deg=(-45.0, 45.0))  # 90 deg up and down: much open sky
HOLED = 3  # the index of the scan with holes in the stream


def _organised_scans(n_scans=5, seed=0):
    """Ray-cast (64 * 180, 3) organised scans of the courtyard along a drive, row by row (a beam per row), a
    no-return as a NaN row; float32 values (as published, so that a PointCloud2 carries them exactly)."""
    rng, scene = np.random.default_rng(seed), courtyard_scene()
    directions = OS0.directions()
    scans = []
    for pose in synthetic_trajectory(n_scans):
        ranges = raycast(scene, pose[:3, 3], directions @ pose[:3, :3].T, OS0.max_range)
        returned = np.isfinite(ranges) & (ranges >= OS0.min_range)
        points = np.full(directions.shape, np.nan)
        noisy = ranges[returned] + rng.normal(0.0, OS0.range_noise, returned.sum())
        points[returned] = directions[returned] * noisy[:, None]
        scans.append(points.astype(np.float32).astype(np.float64))
    return scans


def _finite_rows(points):
    return points[np.isfinite(points).all(axis=1)]


def _dense_flag_lies(points):
    """The organised scan as a 64-row PointCloud2 whose is_dense wrongly says true, decoded as the node does."""
    msg = SimpleNamespace(height=OS0.n_beams, width=OS0.n_azimuth, is_bigendian=False, point_step=12,
                          row_step=12 * OS0.n_azimuth, is_dense=True, data=points.astype("<f4").tobytes(),
                          fields=[SimpleNamespace(name=n, offset=o, datatype=FLOAT32, count=1)
                                  for n, o in zip("xyz", (0, 4, 8))])
    decoded = decode_scan(msg, want_times=False)
    np.testing.assert_array_equal(decoded.points, _finite_rows(points))  # the NaNs dropped, not trusted
    return decoded.points


def _interleaved(points):
    """The finite points with a NaN row after every second one."""
    finite = _finite_rows(points)
    return np.insert(finite, np.arange(2, len(finite), 2), np.nan, axis=0)


def _inf_holes(points):
    """The organised scan with its no-returns as inf (one coordinate -inf, one finite: 'any coordinate')."""
    out = points.copy()
    out[~np.isfinite(points).all(axis=1)] = (np.inf, -np.inf, 0.0)
    return out


ENCODINGS = {"organised_nan": lambda p: p, "interleaved_nan": _interleaved, "is_dense_true_with_nans": _dense_flag_lies,
             "inf_holes": _inf_holes}


def _steps(scans, holed):
    """Each scan's step from a fresh aligner: the scans' finite points, the HOLED one as ``holed``."""
    aligner = ScanAligner(AlignerConfig())
    clouds = [holed if k == HOLED else _finite_rows(scan) for k, scan in enumerate(scans)]
    return [aligner.process(cloud, k * PERIOD, frame_id="lidar") for k, cloud in enumerate(clouds)]


@pytest.fixture(scope="module")
def organised_scans():
    """The scans and the poses of their finite points (the reference every encoding must reproduce)."""
    scans = _organised_scans()
    reference = _steps(scans, _finite_rows(scans[HOLED]))
    assert all(step.accepted for step in reference), [step.reason for step in reference]
    return scans, np.array([step.pose for step in reference])


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_a_scan_with_holes_after_scans_without_aligns_as_its_finite_points(organised_scans, encoding):
    scans, reference = organised_scans
    holed = ENCODINGS[encoding](scans[HOLED])
    share = 1.0 - len(_finite_rows(scans[HOLED])) / OS0.n_beams / OS0.n_azimuth
    assert share > 0.3  # far more than the clean scans before it (none)
    steps = _steps(scans, holed)
    assert steps[HOLED].accepted and not steps[HOLED].warnings, steps[HOLED].reason
    np.testing.assert_allclose([step.pose for step in steps], reference, rtol=0.0, atol=1e-9)
