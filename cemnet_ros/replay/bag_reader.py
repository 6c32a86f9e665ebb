"""Read point clouds + ground truth from rosbag2 bags with ``rosbags`` (no rclpy/DDS).

Accepts a rosbag2 directory (mcap or sqlite3 storage, with metadata.yaml) or a bare ``.mcap``/``.db3`` file.
A cloud message that cannot be used (undecodable CDR, truncated data, bad layout, no point, ...) is reported as
a :class:`SkippedMessage` by :meth:`BagReader.scans`, so that one bad message costs only itself.
"""
from __future__ import annotations

import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Iterator, Optional, Union

import numpy as np
from rosbags.highlevel import AnyReader, AnyReaderError

from cemnet_ros.pipeline.errors import ScanRejected
from cemnet_ros.pipeline.steps.input_checks import stamp_ns
from cemnet_ros.pointcloud2 import CloudError, CloudReport, decode_scan
from cemnet_ros.replay.bag_types import (
    GROUND_TRUTH_TOPIC,
    ODOMETRY,
    POINTCLOUD2,
    POSE_STAMPED,
    TYPESTORE,
    BagError,
    stamp_to_ns,
)
from cemnet_ros.runtime.extrinsic import pose_msg_to_matrix

_GT_TYPES = (POSE_STAMPED, ODOMETRY)


@dataclass
class CloudFrame:
    """One decoded scan."""

    stamp_ns: int  # header stamp (bag receive time when the header stamp is zero)
    points: np.ndarray  # (n,3) float64, finite
    frame_id: str
    report: CloudReport
    times: Optional[np.ndarray] = None  # per-point s relative to the stamp (deskewing); None without a time field
    index: int = 0  # message index on the cloud topic, in bag order
    t_s: float = 0.0  # bag time since the bag's first message, s


@dataclass
class SkippedMessage:
    """A cloud message that gives no pose: which one, when, and why (``kind`` names the problem for counters:
    a :class:`~cemnet_ros.pointcloud2.CloudError` kind, ``invalid`` for undecodable CDR or a malformed message,
    or what the replay adds, e.g. ``preprocessing`` for a scan the aligner rejects)."""

    index: int  # message index on the topic, in bag order
    topic: str
    stamp_ns: int  # header stamp (bag time when the header is zero or unreadable)
    t_s: float  # bag time since the bag's first message, s
    kind: str
    reason: str

    def as_dict(self) -> dict:
        return asdict(self)


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

    def _raw(self, topic: str) -> Iterator[tuple[int, str, bytes]]:
        """(bag time ns, message type, CDR bytes) in bag order; BagError when the storage itself is unreadable
        (nothing after that point can be read)."""
        conns = [c for c in self._reader.connections if c.topic == topic]
        try:
            for conn, bag_ns, raw in self._reader.messages(connections=conns):
                yield bag_ns, conn.msgtype, raw
        except Exception as err:
            raise BagError(f"cannot read {topic} from {self.path} (corrupt bag?): {err!r}") from err

    def _messages(self, topic: str) -> Iterator[tuple[int, object]]:
        for i, (bag_ns, msgtype, raw) in enumerate(self._raw(topic)):
            try:
                msg = self._reader.deserialize(raw, msgtype)
            except Exception as err:
                raise BagError(f"{topic} message {i} of {self.path} cannot be deserialized: {err!r}") from err
            yield bag_ns, msg

    def scans(self, limit: Optional[int] = None) -> Iterator[Union[CloudFrame, SkippedMessage]]:
        """One item per message of the cloud topic (the first ``limit``), in bag order: the decoded scan, or a
        :class:`SkippedMessage` saying why the message gives none."""
        topic, start_ns = self.info.cloud_topic, self._reader.start_time
        for i, (bag_ns, msgtype, raw) in enumerate(self._raw(topic)):
            if limit is not None and i >= limit:
                return
            yield self._scan(i, (bag_ns - start_ns) * 1e-9, bag_ns, msgtype, raw)

    def _scan(self, index: int, t_s: float, bag_ns: int, msgtype: str, raw: bytes
              ) -> Union[CloudFrame, SkippedMessage]:
        topic = self.info.cloud_topic
        try:
            msg = self._reader.deserialize(raw, msgtype)
        except Exception as err:  # noqa: BLE001 - rosbags raises assorted errors on malformed CDR
            return SkippedMessage(index, topic, bag_ns, t_s, "invalid", f"cannot deserialize the message: {err!r}")
        try:  # the node's stamp check: a nanosec out of range would shift the stamp
            stamp = stamp_ns(msg.header.stamp.sec, msg.header.stamp.nanosec) or bag_ns
        except ScanRejected as err:
            return SkippedMessage(index, topic, bag_ns, t_s, err.kind, str(err))
        try:  # an unreadable time field: the scan is used without deskewing, as live
            decoded = decode_scan(msg, want_times=True, stamp_ns=stamp)
        except CloudError as err:
            return SkippedMessage(index, topic, stamp, t_s, err.kind, str(err))
        return CloudFrame(stamp, decoded.points, msg.header.frame_id, decoded.report, decoded.times, index, t_s)

    def clouds(self, limit: Optional[int] = None) -> Iterator[CloudFrame]:
        """Decoded scans in bag order; raises BagError naming the message index when one cannot be decoded."""
        for item in self.scans(limit):
            if isinstance(item, SkippedMessage):
                raise BagError(f"{item.topic} message {item.index}: {item.reason}")
            yield item

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
