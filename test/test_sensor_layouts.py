"""The five ROS 2 drivers' PointCloud2 layouts (docs/sensors.md) through the node's decoding and deskewing.

Each cloud is a synthetic skewed sweep (``cemnet_ros.data.skewed``) written in a driver's exact layout
(``benchmarks/sensor_layouts.py``: fields, datatypes, offsets, point_step, organisation, no-returns, stamp and
time field as the driver's source builds them), serialized to CDR and decoded as the node's worker does. The
points and their times must come out as the sweep measured them: a wrong unit or reference of a time field fails
here (``test_a_wrong_unit_or_reference_fails_the_check`` shows it), and deskewing must bring the drive's error
down as it does for the plain arrays.
"""
from __future__ import annotations

import dataclasses
from functools import lru_cache

import numpy as np
import pytest

from benchmarks import sensor_layouts
from benchmarks.sensor_layouts import EPOCH_NS, LAYOUTS, VARIANTS, decoded, driver_clouds
from cemnet_ros.data.scenes import LidarModel
from cemnet_ros.data.skewed import PERIOD_S, skewed_sequence

LIDAR = LidarModel(n_beams=16, n_azimuth=240)
ALL = {**LAYOUTS, **VARIANTS}
TIME_TOLERANCE = 1e-6  # s: float64 absolute seconds near 1.7e9 s resolve ~0.2 us; a misread is off by >= 0.4 ms


@lru_cache(maxsize=None)
def _sequence(stamp_at: float, n_scans: int = 2):
    return skewed_sequence(n_scans, seed=5, lidar=LIDAR, stamp_at=stamp_at)


def _check_layout(name: str) -> None:
    """Decode scan 1 of a drive in layout ``name`` through the node's path; AssertionError unless the points and
    their times are what the sweep measured, relative to the header stamp."""
    layout = ALL[name]
    sequence = _sequence(layout.stamp_at)
    cloud = driver_clouds(layout, sequence, LIDAR)[1]
    scan = decoded(cloud)
    assert scan.stamp_ns == EPOCH_NS + sequence.stamps_ns[1]
    assert scan.warnings == [], scan.warnings
    # The points: the sweep's returns, every one, no-returns (NaN or at the origin) dropped.
    assert len(scan.points) == len(sequence.scans[1]) == int(cloud.returns.sum())
    np.testing.assert_array_equal(scan.points, cloud.xyz[cloud.returns].astype(np.float64))
    # The times: each point's own (its column's; Hesai: its packet's), in seconds after the header stamp.
    assert scan.times is not None, "the time field was not used"
    truth = cloud.times[cloud.returns]
    np.testing.assert_allclose(scan.times, truth, atol=TIME_TOLERANCE, rtol=0)
    # ... and the sweep lies where the driver stamps it: after the stamp (first point) or before it (last point).
    start = -layout.stamp_at * PERIOD_S
    assert abs(truth.min() - start) < 2 * PERIOD_S / LIDAR.n_azimuth
    assert abs(truth.max() - (start + PERIOD_S)) < (1 + layout.packet_columns) * PERIOD_S / LIDAR.n_azimuth


@pytest.mark.parametrize("name", sorted(ALL))
def test_the_node_reads_each_driver_layout(name):
    _check_layout(name)


@pytest.mark.parametrize("name", sorted(LAYOUTS))
@pytest.mark.parametrize("scale, shift", [(1e3, 0.0), (1e-3, 0.0), (1.0, 0.5 * PERIOD_S), (1.0, -0.5 * PERIOD_S)],
                         ids=["unit_x1000", "unit_x0.001", "reference_half_sweep_late", "reference_half_sweep_early"])
def test_a_wrong_unit_or_reference_fails_the_check(monkeypatch, name, scale, shift):
    """The time conversion deliberately wrong (every reading's result scaled or shifted): the check must fail,
    by a mismatch or because the node no longer finds the field plausible."""
    import cemnet_ros.point_times as point_times

    right = point_times._readings

    def wrong(dtype, stamp_ns, field_name):
        return [(label, lambda v, convert=convert: convert(v) * scale + shift, least)
                for label, convert, least in right(dtype, stamp_ns, field_name)]

    monkeypatch.setattr(point_times, "_readings", wrong)
    with pytest.raises(AssertionError):
        _check_layout(name)


def test_layouts_follow_the_drivers_packing_rules():
    """The offsets as the drivers compute them: sensor_msgs' addPointField packs each field right after the
    previous one (Velodyne, Hesai, RoboSense; Livox's #pragma pack(1) struct likewise); Ouster's PCL point is a C
    struct (x, y, z and a padding float, then the fields at their natural alignment, 16-byte aligned size)."""
    sizes = {sensor_layouts.UINT8: 1, sensor_layouts.UINT16: 2, sensor_layouts.UINT32: 4, sensor_layouts.FLOAT32: 4,
             sensor_layouts.FLOAT64: 8}
    for layout in (LAYOUTS["velodyne"], LAYOUTS["hesai"], LAYOUTS["livox"], LAYOUTS["robosense"]):
        offset = 0
        for _, field_offset, datatype in layout.fields:
            assert field_offset == offset, layout.name
            offset += sizes[datatype]
        assert layout.point_step == offset, layout.name
    ouster = LAYOUTS["ouster"]
    c_struct = np.dtype([("data", "<f4", 4)] + [(n, "<" + sensor_layouts._FORMATS[d]) for n, _, d in ouster.fields[3:]],
                        align=True)
    assert [c_struct.fields[n][1] for n, _, _ in ouster.fields[3:]] == [o for _, o, _ in ouster.fields[3:]]
    assert ouster.point_step == -(-c_struct.itemsize // 16) * 16


@lru_cache(maxsize=None)
def _drive(stamp_at: float):
    """A 10-scan drive (15 m/s, 30 deg/s yaw) stamped at ``stamp_at`` of each sweep."""
    return skewed_sequence(10, seed=0, lidar=LIDAR, stamp_at=stamp_at)


@lru_cache(maxsize=None)
def _drive_error(name: str, with_times: bool) -> float:
    """Position RMSE (m, in the first pose's frame) of the aligner over the drive decoded from layout ``name``
    (``raw@<stamp_at>``: the plain arrays, as test/pipeline/test_deskew.py feeds them)."""
    from cemnet_ros.pipeline.aligner import AlignerConfig, ScanAligner

    raw = name.startswith("raw@")
    sequence = _drive(float(name[4:]) if raw else LAYOUTS[name].stamp_at)
    if raw:
        inputs = [(p.astype(np.float64), t, s) for p, t, s in zip(sequence.scans, sequence.times, sequence.stamps_ns)]
    else:
        scans = [decoded(cloud) for cloud in driver_clouds(LAYOUTS[name], sequence, LIDAR)]
        assert all(scan.times is not None and not scan.warnings for scan in scans)
        inputs = [(scan.points, scan.times, scan.stamp_ns) for scan in scans]
    config = AlignerConfig()
    aligner = ScanAligner(dataclasses.replace(config, preprocess=dataclasses.replace(config.preprocess, deskew=True)))
    poses = [aligner.process(points, stamp, times if with_times else None).pose for points, times, stamp in inputs]
    truth = [np.linalg.inv(sequence.poses[0]) @ pose for pose in sequence.poses]
    return float(np.sqrt(np.mean([np.sum((p[:3, 3] - g[:3, 3]) ** 2) for p, g in zip(poses, truth)])))


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(LAYOUTS))
def test_deskewing_each_driver_layout_brings_the_error_down(name):
    """With the layout's decoded times the drive's error is under half of the same sweeps' without times (the
    plain arrays: the decoded points are the same, test_the_node_reads_each_driver_layout), and as low as with
    the plain arrays' own times (Hesai's per-packet times within a margin). scripts/bench_deskew.py --layouts
    measures both modes on every layout at full size."""
    raw = f"raw@{LAYOUTS[name].stamp_at}"
    on, off, raw_on = _drive_error(name, True), _drive_error(raw, False), _drive_error(raw, True)
    assert on < 0.5 * off, (on, off)
    assert on < 1.2 * raw_on + 0.002, (on, raw_on)
