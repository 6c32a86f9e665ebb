"""Read point clouds + ground truth from rosbag2 bags and write result bags, with ``rosbags`` (no rclpy/DDS).

The writer fills the rosbags (ROS 2 Jazzy) types of what align_node publishes: PoseStamped, nav_msgs/Odometry
with twist and covariances, tf2_msgs/TFMessage and PointCloud2; messages read from another bag (e.g. its
ground truth) are copied with :meth:`BagWriter.write_message`.

Reading accepts a rosbag2 directory (mcap or sqlite3 storage, with metadata.yaml) or a bare ``.mcap``/``.db3``
file. Writing produces one ``.mcap`` file (zstd chunks), built in a temporary directory beside the target and
moved into place only when complete, so a crash never leaves a half-written bag under the final name.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Optional

import numpy as np
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

from cemnet_ros.pipeline.extrinsic import pose_msg_to_matrix
from cemnet_ros.pipeline.odometry_output import UNKNOWN_VARIANCE  # align_node's unmeasured twist
from cemnet_ros.pointcloud2 import CloudError, CloudReport, decode_point_times, decode_xyz, make_pointcloud2

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
ODOMETRY = "nav_msgs/msg/Odometry"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
TF_TOPIC, TF_STATIC_TOPIC = "/tf", "/tf_static"
GROUND_TRUTH_TOPIC = "/ground_truth"
_GT_TYPES = (POSE_STAMPED, ODOMETRY)


class BagError(RuntimeError):
    """A bag that cannot be used: missing, unreadable/corrupt, or without the needed topics."""


# ---------------------------------------------------------------------------------------------- conversions
def stamp_to_ns(stamp) -> int:
    """builtin_interfaces/Time -> integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_stamp(stamp_ns: int):
    """Integer nanoseconds -> rosbags builtin_interfaces/msg/Time."""
    if stamp_ns < 0:
        raise ValueError(f"stamp must be >= 0 ns, got {stamp_ns}")
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return TYPESTORE.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


def matrix_to_pose_msg(transform: np.ndarray):
    """4x4 matrix -> rosbags geometry_msgs/msg/Pose."""
    types = TYPESTORE.types
    qx, qy, qz, qw = Rotation.from_matrix(np.asarray(transform)[:3, :3]).as_quat()
    x, y, z = (float(v) for v in np.asarray(transform)[:3, 3])
    return types["geometry_msgs/msg/Pose"](
        position=types["geometry_msgs/msg/Point"](x=x, y=y, z=z),
        orientation=types["geometry_msgs/msg/Quaternion"](x=float(qx), y=float(qy), z=float(qz), w=float(qw)),
    )


def _header(frame_id: str, stamp_ns: int):
    return TYPESTORE.types["std_msgs/msg/Header"](stamp=ns_to_stamp(stamp_ns), frame_id=frame_id)


# ---------------------------------------------------------------------------------------------- writing
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
        self._connections: dict[str, object] = {}

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
        types = TYPESTORE.types
        msg = make_pointcloud2(types[POINTCLOUD2], types["sensor_msgs/msg/PointField"], points, frame_id,
                               ns_to_stamp(stamp_ns), header_cls=types["std_msgs/msg/Header"])
        self._write(topic, POINTCLOUD2, msg, stamp_ns)

    def write_pose(self, topic: str, transform: np.ndarray, frame_id: str, stamp_ns: int) -> None:
        """PoseStamped: a pose (4x4 ``transform``) in ``frame_id``."""
        msg = TYPESTORE.types[POSE_STAMPED](header=_header(frame_id, stamp_ns), pose=matrix_to_pose_msg(transform))
        self._write(topic, POSE_STAMPED, msg, stamp_ns)

    def write_odometry(self, topic: str, transform: np.ndarray, covariance: np.ndarray, frame_id: str,
                       child_frame_id: str, stamp_ns: int, *, linear: Optional[np.ndarray] = None,
                       angular: Optional[np.ndarray] = None, twist_covariance: Optional[np.ndarray] = None) -> None:
        """nav_msgs/Odometry: the pose of ``child_frame_id`` in ``frame_id`` with its covariance (6x6, ROS order
        x,y,z,roll,pitch,yaw) and the twist in ``child_frame_id`` (REP-105). Without ``twist_covariance`` the
        twist is unknown: zero, with UNKNOWN_VARIANCE on the covariance diagonal (as align_node's first step)."""
        types = TYPESTORE.types
        cov = np.asarray(covariance, dtype=np.float64).reshape(36)
        vec3 = types["geometry_msgs/msg/Vector3"]

        def vector(v) -> object:
            x, y, z = (0.0, 0.0, 0.0) if v is None else (float(c) for c in np.asarray(v, dtype=np.float64))
            return vec3(x=x, y=y, z=z)

        if twist_covariance is None:
            linear, angular, twist_covariance = None, None, np.eye(6) * UNKNOWN_VARIANCE
        twist = types["geometry_msgs/msg/Twist"](linear=vector(linear), angular=vector(angular))
        msg = types[ODOMETRY](
            header=_header(frame_id, stamp_ns),
            child_frame_id=child_frame_id,
            pose=types["geometry_msgs/msg/PoseWithCovariance"](pose=matrix_to_pose_msg(transform), covariance=cov),
            twist=types["geometry_msgs/msg/TwistWithCovariance"](
                twist=twist, covariance=np.asarray(twist_covariance, dtype=np.float64).reshape(36).copy()),
        )
        self._write(topic, ODOMETRY, msg, stamp_ns)

    def write_transform(self, topic: str, transform: np.ndarray, parent_frame: str, child_frame: str,
                        stamp_ns: int) -> None:
        """tf2_msgs/TFMessage with one TransformStamped: ``child_frame`` in ``parent_frame`` (4x4)."""
        types = TYPESTORE.types
        pose = matrix_to_pose_msg(transform)
        p = pose.position
        tf = types["geometry_msgs/msg/TransformStamped"](
            header=_header(parent_frame, stamp_ns), child_frame_id=child_frame,
            transform=types["geometry_msgs/msg/Transform"](
                translation=types["geometry_msgs/msg/Vector3"](x=p.x, y=p.y, z=p.z), rotation=pose.orientation))
        self._write(topic, TF_MESSAGE, types[TF_MESSAGE](transforms=[tf]), stamp_ns)


# ---------------------------------------------------------------------------------------------- reading
@dataclass
class CloudFrame:
    """One decoded scan."""

    stamp_ns: int  # header stamp (bag receive time when the header stamp is zero)
    points: np.ndarray  # (n,3) float64, finite
    frame_id: str
    report: CloudReport
    times: Optional[np.ndarray] = None  # per-point s relative to the stamp (deskewing); None without a time field


@dataclass
class BagInfo:
    path: Path
    cloud_topic: str
    n_clouds: int
    gt_topic: Optional[str]
    n_gt: int
    topics: dict[str, str]  # topic -> message type


class BagReader:
    """Point clouds and (optional) ground-truth poses from one rosbag2 bag.

    ``topic``: the PointCloud2 topic; None = the bag's only PointCloud2 topic (error if there are several).
    ``gt_topic``: PoseStamped or Odometry ground truth; None = ``/ground_truth`` when present, else no GT.
    """

    def __init__(self, path: str | os.PathLike, topic: Optional[str] = None, gt_topic: Optional[str] = None) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise BagError(f"bag not found: {self.path}")
        try:
            self._reader = AnyReader([self.path], default_typestore=TYPESTORE)
            self._reader.open()
        except (AnyReaderError, FileNotFoundError, OSError, ValueError, KeyError) as err:
            raise BagError(f"cannot open bag {self.path}: {err or type(err).__name__}") from err
        except Exception as err:  # rosbags raises assorted errors on corrupt storage files
            raise BagError(f"cannot open bag {self.path} (corrupt or not a rosbag2?): {err!r}") from err
        try:
            self.info = self._inspect(topic, gt_topic)
        except BaseException:
            self.close()
            raise

    def _inspect(self, topic: Optional[str], gt_topic: Optional[str]) -> BagInfo:
        topics = {name: info.msgtype for name, info in self._reader.topics.items()}
        counts = {name: info.msgcount for name, info in self._reader.topics.items()}
        listing = ", ".join(f"{k} [{v}]" for k, v in sorted(topics.items())) or "no topics"
        clouds = [name for name, typ in topics.items() if typ == POINTCLOUD2]
        if topic is None:
            if not clouds:
                raise BagError(f"{self.path} has no {POINTCLOUD2} topic ({listing})")
            if len(clouds) > 1:
                raise BagError(f"{self.path} has several PointCloud2 topics {sorted(clouds)}; choose one with --topic")
            topic = clouds[0]
        elif topic not in topics:
            raise BagError(f"topic {topic} not in {self.path} ({listing})")
        elif topics[topic] != POINTCLOUD2:
            raise BagError(f"topic {topic} is {topics[topic]}, not {POINTCLOUD2}")
        if gt_topic is None:
            gt_topic = GROUND_TRUTH_TOPIC if GROUND_TRUTH_TOPIC in topics else None
        elif gt_topic not in topics:
            raise BagError(f"ground-truth topic {gt_topic} not in {self.path} ({listing})")
        if gt_topic is not None and topics[gt_topic] not in _GT_TYPES:
            raise BagError(f"ground-truth topic {gt_topic} is {topics[gt_topic]}; expected one of {_GT_TYPES}")
        return BagInfo(self.path, topic, counts[topic], gt_topic, counts.get(gt_topic, 0) if gt_topic else 0, topics)

    def close(self) -> None:
        if self._reader.stack is not None:
            self._reader.close()

    def __enter__(self) -> "BagReader":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def messages(self, topic: str) -> Iterator[tuple[int, str, object]]:
        """(bag time ns, message type, deserialized message) of every message on ``topic``, in bag order
        (nothing when the bag has no such topic); e.g. to copy it into another bag."""
        if topic not in self.info.topics:
            return
        msgtype = self.info.topics[topic]
        for bag_ns, msg in self._messages(topic):
            yield bag_ns, msgtype, msg

    def _messages(self, topic: str) -> Iterator[tuple[int, object]]:
        conns = [c for c in self._reader.connections if c.topic == topic]
        try:
            for conn, bag_ns, raw in self._reader.messages(connections=conns):
                yield bag_ns, self._reader.deserialize(raw, conn.msgtype)
        except BagError:
            raise
        except Exception as err:
            raise BagError(f"cannot read {topic} from {self.path} (corrupt bag?): {err!r}") from err

    def clouds(self, limit: Optional[int] = None) -> Iterator[CloudFrame]:
        """Decoded scans in bag order; raises BagError naming the message index when one cannot be decoded."""
        for i, (bag_ns, msg) in enumerate(self._messages(self.info.cloud_topic)):
            if limit is not None and i >= limit:
                return
            try:
                points, report = decode_xyz(msg)
            except CloudError as err:
                raise BagError(f"{self.info.cloud_topic} message {i}: {err}") from err
            stamp = stamp_to_ns(msg.header.stamp) or bag_ns
            try:
                times = decode_point_times(msg, stamp)
            except CloudError:  # an unreadable time field: the scan is used without deskewing, as live
                times = None
            yield CloudFrame(stamp, points, msg.header.frame_id, report, times)

    def ground_truth(self) -> tuple[np.ndarray, np.ndarray, str]:
        """(stamps_ns (n,), poses (n,4,4), frame_id); empty arrays when the bag has no ground truth."""
        if self.info.gt_topic is None:
            return np.zeros(0, dtype=np.int64), np.zeros((0, 4, 4)), ""
        stamps, poses, frame = [], [], ""
        for i, (bag_ns, msg) in enumerate(self._messages(self.info.gt_topic)):
            pose = msg.pose.pose if self.info.topics[self.info.gt_topic] == ODOMETRY else msg.pose
            try:
                poses.append(pose_msg_to_matrix(pose))
            except ValueError as err:
                raise BagError(f"{self.info.gt_topic} message {i}: {err}") from err
            stamps.append(stamp_to_ns(msg.header.stamp) or bag_ns)
            frame = msg.header.frame_id
        return np.asarray(stamps, dtype=np.int64), np.asarray(poses).reshape(-1, 4, 4), frame
