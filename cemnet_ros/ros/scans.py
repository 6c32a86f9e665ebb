"""What the node queues and how the worker decodes it (no rclpy: plain message objects in, arrays out).

The subscription callback only wraps the message (:class:`Incoming`): decoding 2 MB clouds there would take
the CPU the worker needs, and under overload most of them would be dropped anyway. The worker decodes the ones
it gets to (:func:`decode`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from cemnet_ros.pipeline.input_checks import ScanRejected, stamp_ns
from cemnet_ros.pointcloud2 import CloudError, decode_scan


@dataclass
class Incoming:
    """A message as it arrived: not decoded yet (its stamp is read for pairing and ordering)."""

    msg: Any  # sensor_msgs/PointCloud2
    stamp_ns: int
    topic_kind: str  # "input", "source" or "target"

    @classmethod
    def of(cls, msg: Any, topic_kind: str) -> "Incoming":
        """Raises ScanRejected (kind "stamp") for a nanosec outside [0, 1e9)."""
        return cls(msg, stamp_ns(msg.header.stamp.sec, msg.header.stamp.nanosec), topic_kind)


@dataclass
class Scan:
    """A decoded cloud ready for the aligner."""

    msg: Any
    points: np.ndarray
    times: Optional[np.ndarray]  # per-point seconds relative to the stamp, None without a time field
    stamp_ns: int
    n_total: int  # points in the message, finite or not
    warnings: list  # (kind, message): e.g. a time field that could not be used


def decode(item: Incoming, want_times: bool) -> Scan:
    """The cloud's finite xyz (and point times when deskewing); ScanRejected with the layout's fault."""
    try:
        decoded = decode_scan(item.msg, want_times)
    except CloudError as exc:
        raise ScanRejected(f"{item.topic_kind} cloud rejected: {exc}", exc.kind) from None
    warnings = [("time_field", f"{item.topic_kind} cloud not deskewed: {decoded.time_error}")] \
        if decoded.time_error else []
    return Scan(item.msg, decoded.points, decoded.times, item.stamp_ns, decoded.report.n_total, warnings)
