"""The node's queue items: stamps read from CDR bytes, deserialization faults as rejected inputs."""
from __future__ import annotations

import struct

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import PointCloud2, PointField

from benchmarks.hostile import cdr_cases
from cemnet_ros.pipeline.errors import ScanRejected
from cemnet_ros.pointcloud2 import make_pointcloud2
from cemnet_ros.ros.scans import Incoming, cdr_stamp, decode


def _deserialize(payload):
    return deserialize_message(payload, PointCloud2)


def _payload(sec=12, nanosec=345):
    points = np.random.default_rng(0).normal(size=(50, 3))
    return serialize_message(make_pointcloud2(PointCloud2, PointField, points, "lidar", Time(sec=sec, nanosec=nanosec)))


def test_the_stamp_is_read_from_the_cdr_bytes_in_either_byte_order():
    assert cdr_stamp(_payload(12, 345)) == (12, 345)
    big_endian = b"\x00\x00\x00\x00" + struct.pack(">iI", -3, 7)
    assert cdr_stamp(big_endian) == (-3, 7)


def test_a_serialized_cloud_decodes_to_its_points():
    item = Incoming.of(_payload(), "input")
    assert item.stamp_ns == 12 * 10 ** 9 + 345
    scan = decode(item, False, _deserialize)
    assert scan.points.shape == (50, 3) and scan.msg.header.frame_id == "lidar"


@pytest.mark.parametrize("case", cdr_cases(), ids=lambda c: c.name)
def test_bytes_that_are_no_cloud_are_rejected_as_cdr(case):
    payload = case.build(PointCloud2, PointField, None, Time(sec=5, nanosec=6))
    with pytest.raises(ScanRejected) as info:
        decode(Incoming.of(payload, "input"), False, _deserialize)
    assert info.value.kind == "cdr"


def test_a_nanosec_out_of_range_is_rejected_as_stamp():
    payload = bytearray(_payload())
    struct.pack_into("<I", payload, 8, 2 ** 32 - 1)
    with pytest.raises(ScanRejected) as info:
        Incoming.of(bytes(payload), "input")
    assert info.value.kind == "stamp"
