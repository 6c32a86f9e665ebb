"""Bag access for the offline tools, with ``rosbags`` (no rclpy/DDS): one import path for the reader
(bag_reader.py: clouds, ground truth, skipped messages), the writer (bag_writer.py: atomic ``.mcap`` result
bags) and what they share (bag_types.py: typestore, type names, BagError, conversions)."""
from cemnet_ros.replay.bag_reader import BagInfo, BagReader, CloudFrame, SkippedMessage
from cemnet_ros.replay.bag_types import (
    GROUND_TRUTH_TOPIC,
    ODOMETRY,
    POINTCLOUD2,
    POSE_STAMPED,
    TF_MESSAGE,
    TF_STATIC_TOPIC,
    TF_TOPIC,
    TYPESTORE,
    BagError,
    ns_to_stamp,
    stamp_to_ns,
)
from cemnet_ros.replay.bag_writer import BagWriter
from cemnet_ros.runtime.odometry_output import UNKNOWN_VARIANCE

__all__ = [
    "BagError", "BagInfo", "BagReader", "BagWriter", "CloudFrame", "SkippedMessage", "GROUND_TRUTH_TOPIC",
    "ODOMETRY", "POINTCLOUD2", "POSE_STAMPED", "TF_MESSAGE", "TF_STATIC_TOPIC", "TF_TOPIC", "TYPESTORE",
    "UNKNOWN_VARIANCE", "ns_to_stamp", "stamp_to_ns",
]
