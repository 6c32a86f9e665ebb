"""The plausibility checks before registration: each refuses what it should and lets the normal stream pass."""
import numpy as np
import pytest

from cemnet_ros.pipeline.input_checks import InputChecks, InputChecksConfig, ScanRejected, stamp_ns

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


def test_half_nan_is_refused_as_finite_points_or_as_decoded():
    checks = InputChecks(InputChecksConfig())
    last = _stream(checks)
    cloud = _cloud(1000)
    cloud[::2] = np.nan
    with pytest.raises(ScanRejected, match="50% of the points are not finite") as info:
        checks.admit(cloud, None, last + PERIOD, "lidar")
    assert info.value.kind == "non_finite"
    with pytest.raises(ScanRejected, match="50% of the points are not finite"):  # the decoder dropped them
        checks.admit(cloud[1::2], None, last + PERIOD, "lidar", n_total=1000)


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
    assert info.value.kind == "stamp_future"
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
