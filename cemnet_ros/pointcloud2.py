"""Decode and encode sensor_msgs/PointCloud2 xyz without rclpy.

Duck-typed on the message object, so it works with rclpy's ``sensor_msgs.msg.PointCloud2`` as well as the
dataclasses of ``rosbags``: only the attributes ``height``, ``width``, ``fields`` (``name``, ``offset``,
``datatype``, ``count``), ``is_bigendian``, ``point_step``, ``row_step`` and ``data`` are read.

Integer x/y/z fields are rejected rather than converted: their unit (millimetres? raw ticks?) is not part of the
message, so a silent cast would give plausible-looking but wrong geometry.

**No-returns** are dropped, with their times: rows with a NaN or inf coordinate (the organised clouds of Ouster,
Velodyne and RoboSense), and rows exactly at the origin, x = y = z = 0 (Hesai's and Livox's drivers publish a
beam that saw nothing as a point at distance 0: a sensor cannot measure its own origin). docs/sensors.md cites
the drivers' sources.
"""
from __future__ import annotations

import array
from dataclasses import dataclass
from typing import Any, List, Optional, Tuple

import numpy as np

from cemnet_ros.core.geometry import apply_transform
from cemnet_ros.point_times import TIME_FIELDS, TimeFieldError, normalize_point_times

# sensor_msgs/PointField datatype constants.
INT8, UINT8, INT16, UINT16, INT32, UINT32, FLOAT32, FLOAT64 = range(1, 9)
_FLOAT_TYPES = {FLOAT32: "f4", FLOAT64: "f8"}
_NUMPY_TYPES = {INT8: "i1", UINT8: "u1", INT16: "i2", UINT16: "u2", INT32: "i4", UINT32: "u4", FLOAT32: "f4",
                FLOAT64: "f8"}
_TYPE_NAMES = {INT8: "INT8", UINT8: "UINT8", INT16: "INT16", UINT16: "UINT16", INT32: "INT32", UINT32: "UINT32",
               FLOAT32: "FLOAT32", FLOAT64: "FLOAT64"}
_SIZES = {INT8: 1, UINT8: 1, INT16: 2, UINT16: 2, INT32: 4, UINT32: 4, FLOAT32: 4, FLOAT64: 8}


class CloudError(ValueError):
    """A PointCloud2 that cannot be decoded; the message says why, ``kind`` names the problem for counters.

    Kinds: ``empty``, ``missing_field``, ``field_type``, ``layout`` (point_step/row_step too small),
    ``truncated``, ``no_finite`` and, from :func:`decode_point_times` only, ``time_field``.
    """

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


@dataclass
class CloudReport:
    """What :func:`decode_xyz` found: total points in the message and how many were dropped as no-returns
    (non-finite, or exactly at the origin)."""

    n_total: int
    n_valid: int
    n_nonfinite: int
    n_origin: int = 0  # finite rows at exactly (0, 0, 0): a driver's no-returns (Hesai, Livox)


@dataclass
class EncodedCloud:
    """The PointCloud2 payload for float32 x, y, z (little endian, unorganised)."""

    fields: List[Tuple[str, int, int, int]]  # (name, offset, datatype, count)
    point_step: int
    row_step: int
    width: int
    data: bytes
    dense: bool  # every point finite (the message's is_dense: a reader may then skip the NaN test)


def as_bytes(data: Any) -> np.ndarray:
    """``msg.data`` (bytes, array.array('B'), numpy uint8 or a list of ints) as a contiguous uint8 array."""
    if isinstance(data, (bytes, bytearray, memoryview, array.array)):
        return np.frombuffer(data, dtype=np.uint8)
    return np.ascontiguousarray(np.asarray(data, dtype=np.uint8).reshape(-1))


def decode_xyz(msg: Any) -> Tuple[np.ndarray, CloudReport]:
    """Return the measured x, y, z of a PointCloud2 as an (n, 3) float64 array, plus a :class:`CloudReport`.

    Handles any field offsets, point_step/row_step padding, float32/float64, either endianness and organised
    clouds (height > 1) with NaN or inf holes; ``is_dense`` is not trusted (drivers set it wrongly), every point
    is tested. No-returns are dropped: non-finite rows and rows at exactly (0, 0, 0) (module docstring). Raises
    :class:`CloudError` when the cloud is empty, lacks x/y/z, has non-float x/y/z, a point_step or row_step too
    small for its fields, data shorter than row_step * height, or no measured point at all (kind ``no_finite``).
    """
    points, _ = _xyz_rows(msg)
    finite, measured = _measured(points)
    n_valid = int(measured.sum())
    n_nonfinite = len(points) - int(finite.sum())
    report = CloudReport(n_total=len(points), n_valid=n_valid, n_nonfinite=n_nonfinite,
                         n_origin=len(points) - n_nonfinite - n_valid)
    if n_valid == 0:
        raise CloudError("no_finite", f"cloud has no finite point off the origin ({report.n_nonfinite} non-finite, "
                                      f"{report.n_origin} at (0, 0, 0): no-returns)")
    return (points if n_valid == len(points) else points[measured]), report


def _measured(points: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """(finite, measured) row masks of (n, 3) points: measured = finite and not exactly at the origin."""
    finite = np.isfinite(points).all(axis=1)
    return finite, finite & np.any(points != 0.0, axis=1)


def _xyz_rows(msg: Any) -> Tuple[np.ndarray, np.ndarray]:
    """Every row's x, y, z (finite or not) as (height * width, 3) float64, and the data as uint8; validated."""
    buf = as_bytes(msg.data)
    views = _xyz_views(msg, buf)
    points = np.empty((int(msg.height) * int(msg.width), 3), dtype=np.float64)
    with np.errstate(invalid="ignore"):  # a signalling NaN in the data flags its conversion; it stays non-finite
        for axis, view in enumerate(views):
            points[:, axis] = view.reshape(-1)
    return points, buf


def _xyz_views(msg: Any, buf: np.ndarray) -> List[np.ndarray]:
    """(height, width) views of x, y and z into ``buf`` (the message's data as uint8), the layout validated."""
    height, width = int(msg.height), int(msg.width)
    point_step, row_step = int(msg.point_step), int(msg.row_step)
    if height <= 0 or width <= 0:
        raise CloudError("empty", f"empty cloud (height={height}, width={width})")
    fields = {f.name: f for f in msg.fields}
    missing = [name for name in "xyz" if name not in fields]
    if missing:
        raise CloudError("missing_field",
                         f"cloud has no field(s) {', '.join(missing)} (fields: {sorted(fields) or 'none'})")
    endian = ">" if msg.is_bigendian else "<"
    layout = []
    for name in "xyz":
        f = fields[name]
        if f.datatype not in _FLOAT_TYPES:
            type_name = _TYPE_NAMES.get(f.datatype, f"unknown datatype {f.datatype}")
            raise CloudError("field_type",
                             f"field {name} is {type_name}; only FLOAT32/FLOAT64 coordinates are supported")
        if int(f.offset) < 0 or int(f.offset) + _SIZES[f.datatype] > point_step:
            raise CloudError("layout", f"point_step {point_step} is too small for field {name} at offset "
                                       f"{f.offset} ({_SIZES[f.datatype]} bytes)")
        layout.append((int(f.offset), np.dtype(endian + _FLOAT_TYPES[f.datatype])))
    if row_step < width * point_step:
        raise CloudError("layout",
                         f"row_step {row_step} is smaller than width * point_step = {width * point_step}")
    if len(buf) < row_step * height:
        raise CloudError("truncated", f"truncated cloud: {len(buf)} bytes of data, expected row_step * height "
                                      f"= {row_step * height}")
    return [np.ndarray((height, width), dtype=dtype, buffer=buf, offset=offset, strides=(row_step, point_step))
            for offset, dtype in layout]


def decode_point_times(msg: Any, stamp_ns: Optional[int] = None) -> Optional[np.ndarray]:
    """Per-point times of a PointCloud2 as float64 seconds relative to its stamp, or None without a time field.

    Aligned with :func:`decode_xyz`'s points (the same rows, no-returns dropped). The field is the
    first of ``t``, ``time``, ``offset_time``, ``timestamp`` present
    (:data:`~cemnet_ros.point_times.TIME_FIELDS`); its unit is read as
    :func:`~cemnet_ros.point_times.normalize_point_times` documents (integers: ns relative to the stamp;
    floats: s relative, absolute s, absolute ns). ``stamp_ns`` defaults to the header's.
    Raises :class:`CloudError` as :func:`decode_xyz` does, and kind ``time_field`` when the field cannot be read
    or fits no time convention (the caller may then go on without deskewing).
    """
    fields = {f.name: f for f in msg.fields}
    name = next((n for n in TIME_FIELDS if n in fields), None)
    if name is None:
        return None
    f = fields[name]
    if f.datatype not in _NUMPY_TYPES:
        raise CloudError("time_field", f"time field {name} has unknown datatype {f.datatype}")
    points, buf = _xyz_rows(msg)
    point_step, row_step = int(msg.point_step), int(msg.row_step)
    if int(f.offset) < 0 or int(f.offset) + _SIZES[f.datatype] > point_step:
        raise CloudError("time_field", f"point_step {point_step} is too small for time field {name} at offset "
                                       f"{f.offset} ({_SIZES[f.datatype]} bytes)")
    height, width = int(msg.height), int(msg.width)
    dtype = np.dtype((">" if msg.is_bigendian else "<") + _NUMPY_TYPES[f.datatype])
    raw = np.ndarray((height, width), dtype=dtype, buffer=buf, offset=int(f.offset),
                     strides=(row_step, point_step)).reshape(-1)
    _, measured = _measured(points)
    if stamp_ns is None:
        stamp_ns = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
    try:
        return normalize_point_times(raw[measured], stamp_ns, name)
    except TimeFieldError as exc:
        raise CloudError("time_field", str(exc)) from exc


@dataclass
class DecodedScan:
    """What :func:`decode_scan` gives: the measured points, their report, and the point times when asked for."""

    points: np.ndarray
    report: CloudReport
    times: Optional[np.ndarray]  # None without a (usable) time field, or when not asked for
    time_error: str  # why the time field could not be used ("" when it could, or there is none)


def decode_scan(msg: Any, want_times: bool = True, stamp_ns: Optional[int] = None) -> DecodedScan:
    """A scan for the pipeline, as the node and the replay take it: :func:`decode_xyz`, then (``want_times``)
    :func:`decode_point_times`. Raises CloudError for any fault of the cloud (kind ``invalid`` for a message
    that breaks the decoder otherwise); an unusable time field is not a fault: the scan goes on undeskewed."""
    try:
        points, report = decode_xyz(msg)
        times, time_error = None, ""
        if want_times:
            try:
                times = decode_point_times(msg, stamp_ns)
            except CloudError as exc:
                time_error = str(exc)
    except CloudError:
        raise
    except Exception as exc:  # noqa: BLE001 - a malformed message of any other kind is a fault of the cloud
        raise CloudError("invalid", f"{type(exc).__name__}: {exc}") from None
    return DecodedScan(points, report, times, time_error)


def encode_xyz(points: np.ndarray) -> EncodedCloud:
    """Pack (n, 3) points as float32 x, y, z little endian with a 12-byte point_step."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), not {pts.shape}")
    packed = pts.astype("<f4")
    return EncodedCloud(fields=[("x", 0, FLOAT32, 1), ("y", 4, FLOAT32, 1), ("z", 8, FLOAT32, 1)],
                        point_step=12, row_step=12 * len(pts), width=len(pts), data=packed.tobytes(),
                        dense=bool(np.isfinite(packed).all()))


def make_pointcloud2(msg_cls: Any, field_cls: Any, points: np.ndarray, frame_id: str, stamp: Any,
                     header_cls: Any = None) -> Any:
    """Build a PointCloud2 of the given message classes holding ``points`` (float32 xyz).

    Works with rclpy classes (``header_cls`` may be omitted) and with rosbags dataclasses (pass ``header_cls``,
    the ``std_msgs/msg/Header`` class, because those have no default constructors).
    """
    enc = encode_xyz(points)
    fields = [field_cls(name=n, offset=o, datatype=d, count=c) for n, o, d, c in enc.fields]
    body = dict(height=1, width=enc.width, fields=fields, is_bigendian=False, point_step=enc.point_step,
                row_step=enc.row_step, is_dense=enc.dense)
    return _message(msg_cls, body, np.frombuffer(enc.data, dtype=np.uint8), frame_id, stamp, header_cls)


def transformed_cloud(msg_cls: Any, cloud: Any, T_frame_cloud: np.ndarray, frame_id: str,
                      header_cls: Any = None) -> Any:
    """A copy of ``cloud`` with x, y, z moved by ``T_frame_cloud`` into ``frame_id``, every other field kept and
    the stamp too (float32/64 coordinates; classes as in :func:`make_pointcloud2`)."""
    data = as_bytes(cloud.data).copy()
    views = _xyz_views(cloud, data)
    with np.errstate(invalid="ignore"):  # as in _xyz_rows: signalling NaNs stay non-finite, silently
        moved = apply_transform(T_frame_cloud, np.stack([v.reshape(-1).astype(np.float64) for v in views], axis=1))
    for axis, view in enumerate(views):
        view[...] = moved[:, axis].reshape(view.shape)
    body = dict(height=cloud.height, width=cloud.width, fields=list(cloud.fields), is_bigendian=cloud.is_bigendian,
                point_step=cloud.point_step, row_step=cloud.row_step, is_dense=cloud.is_dense)
    return _message(msg_cls, body, data, frame_id, cloud.header.stamp, header_cls)


def _message(msg_cls: Any, body: dict, data: np.ndarray, frame_id: str, stamp: Any, header_cls: Any) -> Any:
    """A PointCloud2 of ``msg_cls``: rclpy's takes its data as bytes, rosbags' as a uint8 array and its header
    in the constructor."""
    is_dataclass = hasattr(msg_cls, "__dataclass_fields__")
    body["data"] = data if is_dataclass else data.tobytes()
    if header_cls is not None:
        return msg_cls(header=header_cls(stamp=stamp, frame_id=frame_id), **body)
    msg = msg_cls(**body)
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    return msg
