"""The PointCloud2 layouts of five ROS 2 LiDAR drivers, filled from a synthetic skewed sweep (test and benchmark
data, not recordings).

Each :class:`Layout` is a driver's cloud as its source builds it (docs/sensors.md cites the files): the fields'
names, datatypes and offsets, ``point_step``, the organisation (``height`` x ``width`` and the order of the
points), what a no-return is (NaN, or a point at the origin), where the header stamp lies in the sweep and how the
per-point time field encodes a point's time (unit, type, reference). :func:`driver_cloud` fills one from a scan of
:func:`cemnet_ros.data.skewed.skewed_sequence`; :func:`decoded` takes it through the node's own path (CDR bytes,
:func:`cemnet_ros.ros.scans.decode`).

The sweep is the synthetic spinning LiDAR's (every azimuth column at its own time) in every layout, Livox's
included: a Livox sensor's non-repetitive pattern is not simulated, only its driver's message.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable, Optional

import numpy as np

from cemnet_ros.data.scenes import LidarModel
from cemnet_ros.data.skewed import SkewedSequence

# sensor_msgs/PointField datatypes
UINT8, UINT16, UINT32, FLOAT32, FLOAT64 = 2, 4, 6, 7, 8
_FORMATS = {UINT8: "u1", UINT16: "u2", UINT32: "u4", FLOAT32: "f4", FLOAT64: "f8"}
EPOCH_NS = 1_700_000_000_000_000_000  # the synthetic drive's t = 0 as an epoch stamp (absolute fields are ~1.7e9 s)
HESAI_COLUMNS_PER_PACKET = 2  # Hesai stamps every point of a packet with the packet's time (2 blocks per packet)


@dataclass(frozen=True)
class Layout:
    """One driver's PointCloud2 (its default configuration unless the name says otherwise)."""

    name: str
    fields: tuple[tuple[str, int, int], ...]  # (name, offset, datatype), in the driver's order
    point_step: int
    time_field: str
    stamp_at: float  # where the header stamp lies in the sweep: 0 = its first point, 1 = its last
    grid: str  # "beam_rows": height = beams (Ouster); "column_rows": height = columns, width = beams (Velodyne,
    # RoboSense); "flat": one row, every point of the sweep; "flat_column": width 1, height = points (RoboSense's
    # dense_points); "hits": one row, only the returns
    no_return: str  # "nan": NaN x/y/z kept in place; "origin": (0, 0, 0); "dropped": not in the cloud
    is_dense: Optional[bool]  # what the driver writes; None: "no NaN in the cloud" (PCL's rule)
    encode_time: Callable[[np.ndarray, int], np.ndarray]  # (times s relative to the stamp, stamp ns) -> raw field
    source: str  # repository and file the layout is read from
    packet_columns: int = 1  # columns whose points share one time (the packet's): Hesai stamps per packet

    def dtype(self, big_endian: bool = False) -> np.dtype:
        end = ">" if big_endian else "<"
        return np.dtype({"names": [f[0] for f in self.fields], "formats": [end + _FORMATS[f[2]] for f in self.fields],
                         "offsets": [f[1] for f in self.fields], "itemsize": self.point_step})


def _ouster_t(times: np.ndarray, stamp_ns: int) -> np.ndarray:
    return np.maximum(np.round(times * 1e9), 0).astype(np.uint32)  # ns since the scan's first column (the stamp)


def _velodyne_time(times: np.ndarray, stamp_ns: int) -> np.ndarray:
    return times.astype(np.float32)  # s relative to the stamp (the last packet's: <= 0)


def _absolute_seconds(times: np.ndarray, stamp_ns: int) -> np.ndarray:
    return stamp_ns * 1e-9 + times  # float64 seconds since the epoch


def _hesai_timestamp(times: np.ndarray, stamp_ns: int) -> np.ndarray:
    # The packet's sensor time in whole microseconds (the stamp is the first packet's), as float64 seconds.
    stamp_us = stamp_ns // 1000
    return (stamp_us + np.round(times * 1e6)) / 1e6


def _livox_timestamp(times: np.ndarray, stamp_ns: int) -> np.ndarray:
    return (stamp_ns + np.round(times * 1e9)).astype(np.float64)  # float64 nanoseconds since the epoch


_XYZI = (("x", 0, FLOAT32), ("y", 4, FLOAT32), ("z", 8, FLOAT32), ("intensity", 12, FLOAT32))

OUSTER = Layout(
    "ouster", (("x", 0, FLOAT32), ("y", 4, FLOAT32), ("z", 8, FLOAT32), ("intensity", 16, FLOAT32),
               ("t", 20, UINT32), ("reflectivity", 24, UINT16), ("ring", 26, UINT16), ("ambient", 28, UINT16),
               ("range", 32, UINT32)),
    48, "t", 0.0, "beam_rows", "nan", None, _ouster_t,
    "ouster-lidar/ouster-ros (jazzy-devel) ouster-ros/include/ouster_ros/os_point.h, src/point_cloud_compose.h")
VELODYNE = Layout(
    "velodyne", _XYZI + (("ring", 16, UINT16), ("time", 18, FLOAT32)),
    22, "time", 1.0, "column_rows", "nan", False, _velodyne_time,
    "ros-drivers/velodyne (ros2) velodyne_pointcloud/src/lib/organized_cloudXYZIRT.cpp, rawdata.cpp")
HESAI = Layout(
    "hesai", _XYZI + (("ring", 16, UINT16), ("timestamp", 18, FLOAT64)),
    26, "timestamp", 0.0, "flat", "origin", False, _hesai_timestamp,
    "HesaiTechnology/HesaiLidar_ROS_2.0 src/manager/source_driver_ros2.hpp", HESAI_COLUMNS_PER_PACKET)
LIVOX = Layout(
    "livox", _XYZI + (("tag", 16, UINT8), ("line", 17, UINT8), ("timestamp", 18, FLOAT64)),
    26, "timestamp", 0.0, "flat", "origin", True, _livox_timestamp,
    "Livox-SDK/livox_ros_driver2 src/lddc.cpp (xfer_format 0), src/comm/comm.h")
ROBOSENSE = Layout(
    "robosense", _XYZI + (("ring", 16, UINT16), ("timestamp", 18, FLOAT64)),
    26, "timestamp", 0.0, "column_rows", "nan", False, _absolute_seconds,
    "RoboSense-LiDAR/rslidar_sdk src/source/source_pointcloud_ros.hpp (POINT_TYPE XYZIRT)")

LAYOUTS = {layout.name: layout for layout in (OUSTER, VELODYNE, HESAI, LIVOX, ROBOSENSE)}

# The same drivers in their other configurations (the layouts' organisation changes, the fields do not).
VARIANTS = {
    "ouster_unorganized": replace(OUSTER, name="ouster_unorganized", grid="hits", no_return="dropped",
                                  is_dense=True),
    "velodyne_unorganized": replace(VELODYNE, name="velodyne_unorganized", grid="hits", no_return="dropped",
                                    is_dense=True),
    "robosense_dense": replace(ROBOSENSE, name="robosense_dense", grid="flat_column", no_return="dropped",
                               is_dense=True),
    "robosense_last_point": replace(ROBOSENSE, name="robosense_last_point", stamp_at=1.0),
}


@dataclass
class SweepGrid:
    """A sweep as the sensor measured it: every (beam, column) cell, hit or not, with its time."""

    xyz: np.ndarray  # (beams, columns, 3) float32, NaN where the beam had no return
    times: np.ndarray  # (beams, columns) float64 s relative to the stamp (a column's time, hit or not)

    @property
    def hit(self) -> np.ndarray:
        return np.isfinite(self.xyz).all(axis=2)


def sweep_grid(points: np.ndarray, times: np.ndarray, lidar: LidarModel, period: float, stamp_at: float
               ) -> SweepGrid:
    """The (beam, column) grid of one skewed scan: its column from its time, its beam from its direction (the
    ray caster puts each point exactly along its beam's direction)."""
    n_beams, n_columns = lidar.n_beams, lidar.n_azimuth
    columns = np.round((np.asarray(times) / period + stamp_at) * n_columns).astype(int)
    if columns.min() < 0 or columns.max() >= n_columns:
        raise ValueError("point times do not match the sweep's columns")
    directions = lidar.directions().reshape(n_beams, n_columns, 3)
    pts = np.asarray(points, dtype=np.float64)
    unit = pts / np.linalg.norm(pts, axis=1, keepdims=True)
    beams = np.argmax(np.einsum("bnk,nk->bn", directions[:, columns], unit), axis=0)
    xyz = np.full((n_beams, n_columns, 3), np.nan, dtype=np.float32)
    xyz[beams, columns] = points
    column_times = (np.arange(n_columns) / n_columns - stamp_at) * period
    return SweepGrid(xyz, np.broadcast_to(column_times, (n_beams, n_columns)).astype(np.float64))


@dataclass
class DriverCloud:
    """A PointCloud2's content in a driver's layout, and what each of its rows truly is."""

    layout: Layout
    height: int
    width: int
    data: bytes
    is_dense: bool
    is_bigendian: bool
    stamp_ns: int
    xyz: np.ndarray  # (height * width, 3) float32: the rows' x, y, z as published (NaN, zeros and all)
    times: np.ndarray  # (height * width,) s relative to the stamp that each row's time field says
    returns: np.ndarray  # (height * width,) bool: the row is a measured point (not a no-return)

    def message(self, msg_cls, field_cls, frame_id: str = "lidar"):
        """As a message of ``msg_cls`` (rclpy's sensor_msgs/PointCloud2; ``field_cls`` its PointField)."""
        from builtin_interfaces.msg import Time

        msg = msg_cls(height=self.height, width=self.width, is_bigendian=self.is_bigendian,
                      point_step=self.layout.point_step, row_step=self.layout.point_step * self.width,
                      is_dense=self.is_dense, data=self.data,
                      fields=[field_cls(name=n, offset=o, datatype=d, count=1) for n, o, d in self.layout.fields])
        msg.header.stamp = Time(sec=self.stamp_ns // 1_000_000_000, nanosec=self.stamp_ns % 1_000_000_000)
        msg.header.frame_id = frame_id
        return msg


def driver_cloud(layout: Layout, grid: SweepGrid, stamp_ns: int, big_endian: bool = False) -> DriverCloud:
    """The sweep ``grid`` (times relative to ``stamp_ns``) in ``layout``: the rows in the driver's order, its
    no-returns, its time field, and the other fields filled with plausible values."""
    n_beams, n_columns = grid.times.shape
    ring = np.broadcast_to(np.arange(n_beams)[:, None], (n_beams, n_columns))
    times = grid.times
    if layout.packet_columns > 1:  # every point of a packet carries the packet's (its first column's) time
        times = times[:, (np.arange(n_columns) // layout.packet_columns) * layout.packet_columns]
    if layout.grid == "beam_rows":  # Ouster: row = ring (channel 0 the top beam), column = azimuth
        order = lambda a: a[::-1].reshape(n_beams * n_columns, *a.shape[2:])  # noqa: E731
        ring = ring[::-1]
        height, width = n_beams, n_columns
    else:  # column by column, the beams of each column in ring order
        order = lambda a: np.swapaxes(a, 0, 1).reshape(n_beams * n_columns, *a.shape[2:])  # noqa: E731
        height, width = n_columns, n_beams
    xyz, row_times, rings, returns = order(grid.xyz), order(times), order(ring), order(grid.hit)
    if layout.no_return == "origin":
        xyz = np.where(returns[:, None], xyz, np.float32(0.0))
    elif layout.no_return == "dropped":
        xyz, row_times, rings, returns = xyz[returns], row_times[returns], rings[returns], returns[returns]
    if layout.grid in ("flat", "hits"):
        height, width = 1, len(xyz)
    elif layout.grid == "flat_column":
        height, width = len(xyz), 1
    rows = np.zeros(len(xyz), dtype=layout.dtype(big_endian))
    for axis, name in enumerate("xyz"):
        rows[name] = xyz[:, axis]
    distance = np.linalg.norm(np.nan_to_num(xyz.astype(np.float64)), axis=1)
    rows["intensity"] = np.where(distance > 0, 1000.0 / np.maximum(distance, 1.0), 0.0)
    rows[layout.time_field] = layout.encode_time(row_times, stamp_ns)
    names = rows.dtype.names
    if "ring" in names:
        rows["ring"] = rings
    if "line" in names:
        rows["line"] = rings % 4
    if "range" in names:  # Ouster: mm, 0 for a no-return
        rows["range"] = np.round(distance * 1000.0).astype(np.uint32)
    is_dense = bool(np.isfinite(xyz).all()) if layout.is_dense is None else layout.is_dense
    return DriverCloud(layout, height, width, rows.tobytes(), is_dense, big_endian, stamp_ns, xyz, row_times,
                       returns)


def driver_clouds(layout: Layout, sequence: SkewedSequence, lidar: LidarModel) -> list[DriverCloud]:
    """Every scan of ``sequence`` (cast with ``lidar`` and ``layout.stamp_at``) in ``layout``, stamped at
    ``EPOCH_NS`` + the sequence's stamps."""
    info = sequence.info
    if abs(info["stamp_at"] - layout.stamp_at) > 1e-12:
        raise ValueError(f"{layout.name} stamps at {layout.stamp_at} of the sweep, the sequence at {info['stamp_at']}")
    return [driver_cloud(layout, sweep_grid(points, times, lidar, info["period_s"], info["stamp_at"]),
                         EPOCH_NS + stamp)
            for points, times, stamp in zip(sequence.scans, sequence.times, sequence.stamps_ns)]


def decoded(cloud: DriverCloud, want_times: bool = True):
    """The cloud through the node's path: an rclpy message, serialized (CDR), then
    :func:`cemnet_ros.ros.scans.decode` as the node's worker calls it. Returns the node's ``Scan``."""
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import PointCloud2, PointField

    from cemnet_ros.ros.scans import Incoming, decode

    payload = serialize_message(cloud.message(PointCloud2, PointField))
    return decode(Incoming.of(payload, "input"), want_times, lambda data: deserialize_message(data, PointCloud2))
