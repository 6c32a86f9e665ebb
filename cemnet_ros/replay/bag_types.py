"""What the bag reader and writer share: the ROS 2 Jazzy typestore, message type names, BagError and the
stamp/pose conversions between rosbags messages and numpy."""
from __future__ import annotations

import numpy as np
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

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


def header(frame_id: str, stamp_ns: int):
    """rosbags std_msgs/msg/Header."""
    return TYPESTORE.types["std_msgs/msg/Header"](stamp=ns_to_stamp(stamp_ns), frame_id=frame_id)
