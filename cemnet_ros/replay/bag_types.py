"""What the bag reader and writer share: the ROS 2 Jazzy typestore, message type names, BagError, stamp
conversions and the rosbags class lookup that the shared message fillers (:mod:`cemnet_ros.pose_messages`) use."""
from __future__ import annotations

from rosbags.typesys import Stores, get_typestore

from cemnet_ros import pose_messages

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
ODOMETRY = "nav_msgs/msg/Odometry"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
TF_TOPIC, TF_STATIC_TOPIC = "/tf", "/tf_static"
GROUND_TRUTH_TOPIC = "/ground_truth"


class BagError(RuntimeError):
    """A bag that cannot be used: missing, unreadable/corrupt, or without the needed topics."""


def stamp_to_ns(stamp) -> int:
    """builtin_interfaces/Time -> integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def rosbags_type(name: str):
    """The rosbags (Jazzy) class of a full type name, e.g. ``"nav_msgs/msg/Odometry"``: the lookup that
    :mod:`cemnet_ros.pose_messages` fills the writer's messages with."""
    return TYPESTORE.types[name]


def ns_to_stamp(stamp_ns: int):
    """Integer nanoseconds -> rosbags builtin_interfaces/msg/Time."""
    return pose_messages.stamp(rosbags_type, stamp_ns)


def header(frame_id: str, stamp_ns: int):
    """rosbags std_msgs/msg/Header."""
    return pose_messages.header(rosbags_type, frame_id, ns_to_stamp(stamp_ns))
