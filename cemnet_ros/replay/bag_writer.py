"""Write result bags with ``rosbags`` (no rclpy/DDS): one ``.mcap`` file (zstd chunks), atomically.

The writer fills the rosbags (ROS 2 Jazzy) types of what align_node publishes, with the node's own fillers
(:mod:`cemnet_ros.pose_messages`, :func:`~cemnet_ros.pointcloud2.make_pointcloud2`): PoseStamped,
nav_msgs/Odometry with twist and covariances, tf2_msgs/TFMessage and PointCloud2; messages read from another
bag (e.g. its ground truth) are copied with :meth:`BagWriter.write_message`. The bag is built in a temporary
directory beside the target and moved into place only when complete, so a crash never leaves a half-written
bag under the final name.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path
from typing import Optional

import numpy as np
from rosbags.interfaces import Connection
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

from cemnet_ros import pose_messages
from cemnet_ros.pointcloud2 import make_pointcloud2
from cemnet_ros.replay.bag_types import (
    ODOMETRY,
    POINTCLOUD2,
    POSE_STAMPED,
    TF_MESSAGE,
    TYPESTORE,
    header,
    ns_to_stamp,
    rosbags_type,
)


class BagWriter:
    """Write clouds, poses and odometry into a single rosbag2 ``.mcap`` file, atomically.

    Use as a context manager; the file appears at ``path`` only after a clean exit (an existing file there is
    replaced only when ``overwrite`` is set, and only at that moment).
    """

    def __init__(self, path: str | os.PathLike, *, compress: bool = True, overwrite: bool = False) -> None:
        self.path = Path(path)
        if self.path.suffix != ".mcap":
            raise ValueError(f"output bag must end in .mcap: {self.path}")
        if self.path.is_dir() or (self.path.exists() and not overwrite):
            raise FileExistsError(f"{self.path} exists already, not overwriting")
        self.compress = compress
        self._tmpdir: Optional[Path] = None
        self._writer: Optional[Writer] = None
        self._connections: dict[str, Connection] = {}

    def __enter__(self) -> "BagWriter":
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmpdir = Path(tempfile.mkdtemp(prefix=f".{self.path.stem}.", dir=self.path.parent))
        self._writer = Writer(self._tmpdir / self.path.stem, version=9, storage_plugin=StoragePlugin.MCAP)
        if self.compress:
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._writer.open()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        assert self._writer is not None and self._tmpdir is not None
        try:
            if exc_type is None:
                self._writer.close()
                written = self._tmpdir / self.path.stem / f"{self.path.stem}.mcap"
                os.chmod(written, 0o644)
                os.replace(written, self.path)
            else:
                self._writer.abort()
        finally:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            self._writer = None

    def write_message(self, topic: str, msgtype: str, msg, stamp_ns: int) -> None:
        """Any message of a type in the Jazzy typestore, e.g. one read from another bag (same content and type);
        ``stamp_ns`` is the bag (log) time."""
        self._write(topic, msgtype, msg, stamp_ns)

    def _write(self, topic: str, msgtype: str, msg, stamp_ns: int) -> None:
        if self._writer is None:
            raise RuntimeError("BagWriter is not open (use it as a context manager)")
        conn = self._connections.get(topic)
        if conn is None:
            conn = self._writer.add_connection(topic, msgtype, typestore=TYPESTORE)
            self._connections[topic] = conn
        elif conn.msgtype != msgtype:
            raise ValueError(f"topic {topic} already carries {conn.msgtype}, not {msgtype}")
        self._writer.write(conn, int(stamp_ns), TYPESTORE.serialize_cdr(msg, msgtype))

    def write_cloud(self, topic: str, points: np.ndarray, frame_id: str, stamp_ns: int) -> None:
        """PointCloud2 with float32 x, y, z (little endian, unorganised)."""
        msg = make_pointcloud2(rosbags_type(POINTCLOUD2), rosbags_type("sensor_msgs/msg/PointField"), points,
                               frame_id, ns_to_stamp(stamp_ns), header_cls=rosbags_type("std_msgs/msg/Header"))
        self._write(topic, POINTCLOUD2, msg, stamp_ns)

    def write_pose(self, topic: str, transform: np.ndarray, frame_id: str, stamp_ns: int) -> None:
        """PoseStamped: a pose (4x4 ``transform``) in ``frame_id``."""
        msg = pose_messages.pose_stamped(rosbags_type, header(frame_id, stamp_ns), transform)
        self._write(topic, POSE_STAMPED, msg, stamp_ns)

    def write_odometry(self, topic: str, transform: np.ndarray, covariance: np.ndarray, frame_id: str,
                       child_frame_id: str, stamp_ns: int, *, linear: Optional[np.ndarray] = None,
                       angular: Optional[np.ndarray] = None, twist_covariance: Optional[np.ndarray] = None) -> None:
        """nav_msgs/Odometry of ``child_frame_id`` in ``frame_id``, as :func:`cemnet_ros.pose_messages.odometry`
        fills it (covariances 6x6 in ROS order; without ``twist_covariance`` the twist is unknown)."""
        msg = pose_messages.odometry(rosbags_type, header(frame_id, stamp_ns), child_frame_id, transform, covariance,
                                     linear=linear, angular=angular, twist_covariance=twist_covariance)
        self._write(topic, ODOMETRY, msg, stamp_ns)

    def write_transform(self, topic: str, transform: np.ndarray, parent_frame: str, child_frame: str,
                        stamp_ns: int) -> None:
        """tf2_msgs/TFMessage with one TransformStamped: ``child_frame`` in ``parent_frame`` (4x4)."""
        msg = pose_messages.tf_message(rosbags_type, header(parent_frame, stamp_ns), child_frame, transform)
        self._write(topic, TF_MESSAGE, msg, stamp_ns)
