"""PointCloud2 decoding over every layout the node may meet, and every way a cloud can be broken."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from cemnet_ros.pointcloud2 import (
    FLOAT32,
    FLOAT64,
    INT16,
    UINT8,
    CloudError,
    decode_scan,
    decode_xyz,
    encode_xyz,
    make_pointcloud2,
    transformed_cloud,
)


def field(name, offset, datatype, count=1):
    return SimpleNamespace(name=name, offset=offset, datatype=datatype, count=count)


def cloud(points, *, dtype="<f4", offsets=(0, 4, 8), point_step=None, row_pad=0, height=1, extra=(),
          datatype=None):
    """A duck-typed PointCloud2 holding ``points`` (height * width, 3) at the given layout."""
    points = np.asarray(points, dtype=np.float64)
    size = np.dtype(dtype).itemsize
    point_step = point_step or max(offsets) + size
    width = len(points) // height
    row_step = width * point_step + row_pad
    data = bytearray(row_step * height)
    for i, p in enumerate(points):
        r, c = divmod(i, width)
        for off, v in zip(offsets, p):
            start = r * row_step + c * point_step + off
            data[start:start + size] = np.array(v, dtype=dtype).tobytes()
    datatype = datatype or (FLOAT32 if size == 4 else FLOAT64)
    fields = [field(n, o, datatype) for n, o in zip("xyz", offsets)] + list(extra)
    return SimpleNamespace(height=height, width=width, fields=fields, is_bigendian=dtype.startswith(">"),
                           point_step=point_step, row_step=row_step, data=bytes(data), is_dense=False)


RNG = np.random.default_rng(0)
PTS = RNG.normal(size=(12, 3)) * 10


def test_plain_float32():
    out, report = decode_xyz(cloud(PTS))
    np.testing.assert_allclose(out, PTS, rtol=1e-6)
    assert out.dtype == np.float64 and report.n_total == 12 and report.n_nonfinite == 0


@pytest.mark.parametrize("dtype", ["<f8", ">f4", ">f8"])
def test_float64_and_big_endian(dtype):
    size = np.dtype(dtype).itemsize
    out, _ = decode_xyz(cloud(PTS, dtype=dtype, offsets=(0, size, 2 * size)))
    np.testing.assert_allclose(out, PTS, rtol=1e-6)


def test_offsets_padding_and_extra_fields():
    # Velodyne-like: x y z at 0 4 8, intensity at 16, ring at 20, point_step 32, 7 bytes of row padding.
    extra = (field("intensity", 16, FLOAT32), field("ring", 20, UINT8))
    out, _ = decode_xyz(cloud(PTS, offsets=(0, 4, 8), point_step=32, row_pad=7, extra=extra))
    np.testing.assert_allclose(out, PTS, rtol=1e-6)
    # Shuffled order: z first, x last, unaligned offsets.
    out, _ = decode_xyz(cloud(PTS, offsets=(9, 5, 1), point_step=15))
    np.testing.assert_allclose(out, PTS, rtol=1e-6)


def test_organised_cloud_with_nans():
    pts = PTS.copy()
    pts[[1, 5]] = np.nan
    pts[7, 2] = np.inf
    out, report = decode_xyz(cloud(pts, height=3, row_pad=4))
    keep = np.isfinite(pts).all(1)
    np.testing.assert_allclose(out, PTS[keep], rtol=1e-6)
    assert report.n_total == 12 and report.n_valid == 9 and report.n_nonfinite == 3


@pytest.mark.parametrize("is_dense", [True, False])
def test_holes_round_trip_dropped_with_their_times_whatever_is_dense_says(is_dense):
    from builtin_interfaces.msg import Time
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import PointCloud2, PointField

    pts = PTS.astype(np.float32).astype(np.float64)
    pts[[0, 4]] = np.nan  # no-returns of a 3 x 4 organised cloud, as NaN ...
    pts[[6, 11]] = np.inf  # ... as inf ...
    pts[9, 1] = -np.inf  # ... and in one coordinate only
    rows = np.zeros(12, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("t", "<u4")])
    rows["x"], rows["y"], rows["z"] = pts.T
    rows["t"] = np.arange(12) * 1000  # ns after the stamp (Ouster)
    msg = PointCloud2(height=3, width=4, is_bigendian=False, point_step=16, row_step=64, is_dense=is_dense,
                      data=rows.tobytes(), fields=[PointField(name=n, offset=o, datatype=d, count=1) for n, o, d in
                                                   (("x", 0, FLOAT32), ("y", 4, FLOAT32), ("z", 8, FLOAT32),
                                                    ("t", 12, PointField.UINT32))])
    msg.header.stamp = Time(sec=5, nanosec=0)
    decoded = decode_scan(deserialize_message(serialize_message(msg), PointCloud2))
    keep = np.isfinite(pts).all(axis=1)
    np.testing.assert_array_equal(decoded.points, pts[keep])
    np.testing.assert_allclose(decoded.times, np.flatnonzero(keep) * 1e-6)
    assert (decoded.report.n_total, decoded.report.n_valid, decoded.report.n_nonfinite) == (12, 7, 5)


def test_make_pointcloud2_says_dense_only_when_every_point_is_finite():
    from builtin_interfaces.msg import Time
    from sensor_msgs.msg import PointCloud2, PointField

    holed = PTS.copy()
    holed[3, 2] = np.nan
    dense = make_pointcloud2(PointCloud2, PointField, PTS, "lidar", Time())
    sparse = make_pointcloud2(PointCloud2, PointField, holed, "lidar", Time())
    assert dense.is_dense and not sparse.is_dense
    np.testing.assert_allclose(decode_xyz(sparse)[0], np.delete(PTS, 3, axis=0), rtol=1e-6)


def test_data_types_of_rclpy_and_rosbags():
    msg = cloud(PTS)
    for data in (np.frombuffer(msg.data, np.uint8), list(msg.data), bytearray(msg.data)):
        out, _ = decode_xyz(SimpleNamespace(**{**vars(msg), "data": data}))
        np.testing.assert_allclose(out, PTS, rtol=1e-6)


@pytest.mark.parametrize("mutate, kind, words", [
    (lambda m: m.__dict__.update(width=0, data=b""), "empty", "empty"),
    (lambda m: m.__dict__.update(height=0), "empty", "empty"),
    (lambda m: m.__dict__.update(fields=[f for f in m.fields if f.name != "y"]), "missing_field", "y"),
    (lambda m: m.__dict__.update(fields=[]), "missing_field", "x, y, z"),
    (lambda m: m.fields[2].__dict__.update(datatype=INT16), "field_type", "INT16"),
    (lambda m: m.fields[0].__dict__.update(datatype=42), "field_type", "unknown datatype 42"),
    (lambda m: m.__dict__.update(data=m.data[:-1]), "truncated", "truncated"),
    (lambda m: m.__dict__.update(point_step=8, row_step=8 * m.width), "layout", "point_step 8"),
    (lambda m: m.__dict__.update(row_step=m.row_step - 1), "layout", "row_step"),
])
def test_bad_clouds_raise_clear_errors(mutate, kind, words):
    msg = cloud(PTS)
    mutate(msg)
    with pytest.raises(CloudError, match=words) as err:
        decode_xyz(msg)
    assert err.value.kind == kind and isinstance(err.value, ValueError)


def test_all_nan_cloud_is_rejected():
    with pytest.raises(CloudError, match="no finite") as err:
        decode_xyz(cloud(np.full((4, 3), np.nan)))
    assert err.value.kind == "no_finite"


def test_no_returns_at_the_origin_are_dropped_with_their_times():
    # Hesai's and Livox's drivers publish a beam that saw nothing as (0, 0, 0): not a point, like NaN.
    pts = PTS.copy()
    pts[[2, 8]] = 0.0  # no-returns
    pts[5, 1] = np.nan
    pts[10] = [0.0, 0.0, 3.0]  # on an axis: a measurement
    pts[11] = [-0.0, 0.0, 0.0]  # negative zero is the origin too
    rows = np.zeros(12, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("timestamp", "<f8")])
    rows["x"], rows["y"], rows["z"] = pts.T
    rows["timestamp"] = 5.0 + np.arange(12) * 1e-3  # absolute seconds (Hesai); the stamp is 5 s
    msg = SimpleNamespace(height=1, width=12, is_bigendian=False, point_step=20, row_step=240, data=rows.tobytes(),
                          fields=[field("x", 0, FLOAT32), field("y", 4, FLOAT32), field("z", 8, FLOAT32),
                                  field("timestamp", 12, FLOAT64)],
                          header=SimpleNamespace(stamp=SimpleNamespace(sec=5, nanosec=0)))
    decoded = decode_scan(msg)
    keep = np.array([i not in (2, 5, 8, 11) for i in range(12)])
    np.testing.assert_array_equal(decoded.points, pts[keep].astype(np.float32))
    np.testing.assert_allclose(decoded.times, np.flatnonzero(keep) * 1e-3, atol=1e-9)
    assert (decoded.report.n_total, decoded.report.n_valid, decoded.report.n_nonfinite, decoded.report.n_origin) \
        == (12, 8, 1, 3)
    with pytest.raises(CloudError, match=r"no finite point off the origin \(1 non-finite, 3 at") as err:
        decode_xyz(cloud(np.vstack([np.zeros((3, 3)), np.full((1, 3), np.nan)])))
    assert err.value.kind == "no_finite"


def test_encode_round_trip():
    enc = encode_xyz(PTS)
    assert enc.point_step == 12 and enc.row_step == 12 * len(PTS) and len(enc.data) == enc.row_step
    msg = SimpleNamespace(height=1, width=enc.width, is_bigendian=False, point_step=enc.point_step,
                          row_step=enc.row_step, data=enc.data, fields=[field(*f) for f in enc.fields])
    out, _ = decode_xyz(msg)
    np.testing.assert_allclose(out, PTS.astype(np.float32), rtol=0, atol=0)
    with pytest.raises(ValueError):
        encode_xyz(np.zeros((3, 2)))


def test_make_pointcloud2_rclpy_round_trip():
    from builtin_interfaces.msg import Time
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import PointCloud2, PointField

    msg = make_pointcloud2(PointCloud2, PointField, PTS, "lidar", Time(sec=3, nanosec=7))
    back = deserialize_message(serialize_message(msg), PointCloud2)
    assert back.header.frame_id == "lidar" and back.header.stamp.sec == 3 and back.header.stamp.nanosec == 7
    np.testing.assert_allclose(decode_xyz(back)[0], PTS, rtol=1e-6)


def test_make_pointcloud2_rosbags_round_trip():
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    types = store.types
    stamp = types["builtin_interfaces/msg/Time"](sec=1, nanosec=2)
    msg = make_pointcloud2(types["sensor_msgs/msg/PointCloud2"], types["sensor_msgs/msg/PointField"], PTS,
                           "cam", stamp, header_cls=types["std_msgs/msg/Header"])
    raw = store.serialize_cdr(msg, "sensor_msgs/msg/PointCloud2")
    back = store.deserialize_cdr(raw, "sensor_msgs/msg/PointCloud2")
    assert back.header.frame_id == "cam"
    np.testing.assert_allclose(decode_xyz(back)[0], PTS, rtol=1e-6)


@pytest.mark.parametrize("kind", ["rclpy", "rosbags"])
def test_transformed_cloud_moves_xyz_and_keeps_every_other_byte(kind):
    from cemnet_ros.core.geometry import apply_transform
    from cemnet_ros.runtime.extrinsic import pose_from_xyz_rpy

    # Organised, big-endian float64, an intensity field between the coordinates' and 5 bytes of row padding.
    extra = (field("intensity", 24, FLOAT32),)
    source = cloud(PTS, dtype=">f8", offsets=(0, 8, 16), point_step=32, row_pad=5, height=2, extra=extra)
    data = bytearray(source.data)
    for i in range(12):  # an intensity per point, which must come through untouched
        r, c = divmod(i, 6)
        data[r * source.row_step + c * 32 + 24:][:4] = np.array(i + 0.5, dtype=">f4").tobytes()
    source.data = bytes(data)
    T = pose_from_xyz_rpy((1.0, -2.0, 0.5, 0.1, 0.2, -0.3))
    if kind == "rclpy":
        from builtin_interfaces.msg import Time
        from sensor_msgs.msg import PointCloud2

        source.header = SimpleNamespace(stamp=Time(sec=4, nanosec=9), frame_id="lidar")
        moved = transformed_cloud(PointCloud2, source, T, "odom")
    else:
        from cemnet_ros.replay.bag_types import rosbags_type

        source.header = SimpleNamespace(stamp=rosbags_type("builtin_interfaces/msg/Time")(sec=4, nanosec=9),
                                        frame_id="lidar")
        moved = transformed_cloud(rosbags_type("sensor_msgs/msg/PointCloud2"), source, T, "odom",
                                  header_cls=rosbags_type("std_msgs/msg/Header"))
    assert moved.header.frame_id == "odom" and moved.header.stamp.nanosec == 9
    assert (moved.height, moved.width, moved.row_step, moved.is_bigendian) == (2, 6, source.row_step, True)
    np.testing.assert_allclose(decode_xyz(moved)[0], apply_transform(T, PTS), rtol=1e-12)
    out, before = np.frombuffer(bytes(moved.data), dtype=np.uint8), np.frombuffer(source.data, dtype=np.uint8)
    coordinate_bytes = np.zeros(len(before), dtype=bool)
    for r in range(2):
        for c in range(6):
            coordinate_bytes[r * source.row_step + c * 32:][:24] = True
    np.testing.assert_array_equal(out[~coordinate_bytes], before[~coordinate_bytes])
