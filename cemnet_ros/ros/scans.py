"""What the node queues and how the worker decodes it (no rclpy: CDR bytes and a deserializer in, arrays out).

The subscriptions take messages raw (their CDR bytes): deserializing a 2 MB cloud costs ~1-2 ms of the
executor's time and the GIL, and under overload most messages are dropped anyway. The callback reads only the
stamp (:class:`Incoming`, for ordering and pairing); the worker deserializes and decodes the ones it gets to
(:func:`decode`), so a malformed byte stream is a rejected input, not an executor exception.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any, Callable, Optional

import numpy as np

from cemnet_ros.pipeline.errors import ScanRejected
from cemnet_ros.pipeline.steps.input_checks import stamp_ns
from cemnet_ros.pointcloud2 import CloudError, decode_scan

# The encapsulation identifiers of plain CDR (XCDR1: ROS 2's) and plain XCDR2: the byte order of what follows.
CDR_BYTE_ORDER = {b"\x00\x00": ">", b"\x00\x01": "<", b"\x00\x06": ">", b"\x00\x07": "<"}
HEADER_STAMP_OFFSET = 4  # after the encapsulation: std_msgs/Header.stamp, int32 sec then uint32 nanosec


def cdr_stamp(payload: bytes) -> tuple[int, int]:
    """(sec, nanosec) of a serialized message that starts with a std_msgs/Header; ValueError if not CDR."""
    order = CDR_BYTE_ORDER.get(bytes(payload[:2]))
    if order is None:
        raise ValueError(f"unknown CDR encapsulation {bytes(payload[:2]).hex() or 'none'}")
    if len(payload) < HEADER_STAMP_OFFSET + 8:
        raise ValueError(f"{len(payload)} bytes end before the header's stamp")
    sec, nanosec = struct.unpack_from(order + "iI", payload, HEADER_STAMP_OFFSET)
    return sec, nanosec


@dataclass
class Incoming:
    """A message as the subscription took it: CDR bytes, not deserialized yet, and its stamp."""

    payload: bytes
    stamp_ns: int
    topic_kind: str  # "input", "source" or "target"

    @classmethod
    def of(cls, payload: bytes, topic_kind: str) -> "Incoming":
        """Raises ScanRejected: kind "cdr" for bytes that are not a serialized message, "stamp" for a nanosec
        outside [0, 1e9)."""
        try:
            sec, nanosec = cdr_stamp(payload)
        except ValueError as exc:
            raise ScanRejected(f"not a serialized PointCloud2: {exc}", "cdr") from None
        return cls(payload, stamp_ns(sec, nanosec), topic_kind)


@dataclass
class Scan:
    """A decoded cloud ready for the aligner."""

    msg: Any  # the deserialized sensor_msgs/PointCloud2
    points: np.ndarray
    times: Optional[np.ndarray]  # per-point seconds relative to the stamp, None without a time field
    stamp_ns: int
    warnings: list  # (kind, message): e.g. a time field that could not be used


def decode(item: Incoming, want_times: bool, deserialize: Callable[[bytes], Any]) -> Scan:
    """The cloud's finite xyz (and point times when deskewing); ScanRejected with the fault: "cdr" for bytes that
    do not deserialize, the layout's kind otherwise."""
    try:
        msg = deserialize(item.payload)
    except Exception as exc:  # noqa: BLE001 - rmw raises RMWError, a malformed stream anything
        reason = (str(exc).splitlines() or [type(exc).__name__])[0]
        raise ScanRejected(f"{item.topic_kind} message does not deserialize as PointCloud2: {reason}", "cdr") \
            from None
    try:
        decoded = decode_scan(msg, want_times)
    except CloudError as exc:
        raise ScanRejected(f"{item.topic_kind} cloud rejected: {exc}", exc.kind) from None
    warnings = [("time_field", f"{item.topic_kind} cloud not deskewed: {decoded.time_error}")] \
        if decoded.time_error else []
    return Scan(msg, decoded.points, decoded.times, item.stamp_ns, warnings)
