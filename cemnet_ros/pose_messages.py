"""Stamps, headers, poses, odometry and TF messages from numpy, written once for both kinds of message class.

align_node fills rclpy's generated classes, the replay's bag writer the dataclasses of ``rosbags``: both are
built here with keyword arguments, from the classes that a ``types`` lookup gives by full type name
(``"geometry_msgs/msg/Pose"``), so a replayed bag carries the very message the node publishes (as
:func:`~cemnet_ros.pointcloud2.make_pointcloud2` does for clouds). No rclpy and no rosbags import here.
"""
from __future__ import annotations

from typing import Any, Callable, Optional

import numpy as np
from scipy.spatial.transform import Rotation

from cemnet_ros.runtime.odometry_output import UNKNOWN_VARIANCE

MessageTypes = Callable[[str], Any]  # full type name -> message class


def stamp(types: MessageTypes, stamp_ns: int) -> Any:
    """builtin_interfaces/Time of integer nanoseconds (>= 0)."""
    if stamp_ns < 0:
        raise ValueError(f"stamp must be >= 0 ns, got {stamp_ns}")
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return types("builtin_interfaces/msg/Time")(sec=sec, nanosec=nanosec)


def header(types: MessageTypes, frame_id: str, time: Any) -> Any:
    """std_msgs/Header; ``time`` is a builtin_interfaces/Time of the same kind (e.g. an input's stamp)."""
    return types("std_msgs/msg/Header")(stamp=time, frame_id=frame_id)


def _vector3(types: MessageTypes, values: Any) -> Any:
    x, y, z = (float(v) for v in np.asarray(values, dtype=np.float64).reshape(3))
    return types("geometry_msgs/msg/Vector3")(x=x, y=y, z=z)


def _quaternion(types: MessageTypes, T: np.ndarray) -> Any:
    x, y, z, w = (float(v) for v in Rotation.from_matrix(np.asarray(T, dtype=np.float64)[:3, :3]).as_quat())
    return types("geometry_msgs/msg/Quaternion")(x=x, y=y, z=z, w=w)


def _covariance(values: np.ndarray) -> np.ndarray:
    """A 6x6 covariance as the 36 float64 values both message kinds take."""
    return np.asarray(values, dtype=np.float64).reshape(36).copy()


def pose(types: MessageTypes, T_parent_child: np.ndarray) -> Any:
    """geometry_msgs/Pose of a 4x4 transform."""
    x, y, z = (float(v) for v in np.asarray(T_parent_child, dtype=np.float64)[:3, 3])
    return types("geometry_msgs/msg/Pose")(position=types("geometry_msgs/msg/Point")(x=x, y=y, z=z),
                                           orientation=_quaternion(types, T_parent_child))


def pose_stamped(types: MessageTypes, head: Any, T_frame_child: np.ndarray) -> Any:
    """geometry_msgs/PoseStamped: a pose in the header's frame."""
    return types("geometry_msgs/msg/PoseStamped")(header=head, pose=pose(types, T_frame_child))


def odometry(types: MessageTypes, head: Any, child_frame: str, T_frame_child: np.ndarray,
             pose_covariance: np.ndarray, *, linear: Optional[np.ndarray] = None,
             angular: Optional[np.ndarray] = None, twist_covariance: Optional[np.ndarray] = None) -> Any:
    """nav_msgs/Odometry: the pose of ``child_frame`` in the header's frame with its covariance (6x6, ROS order
    x, y, z, roll, pitch, yaw) and the twist in ``child_frame`` (REP-105). Without ``twist_covariance`` the
    twist is unknown: zero, with UNKNOWN_VARIANCE on the covariance diagonal (as align_node's first step)."""
    if twist_covariance is None:
        linear, angular, twist_covariance = None, None, np.eye(6) * UNKNOWN_VARIANCE
    twist = types("geometry_msgs/msg/Twist")(linear=_vector3(types, np.zeros(3) if linear is None else linear),
                                             angular=_vector3(types, np.zeros(3) if angular is None else angular))
    return types("nav_msgs/msg/Odometry")(
        header=head, child_frame_id=child_frame,
        pose=types("geometry_msgs/msg/PoseWithCovariance")(pose=pose(types, T_frame_child),
                                                           covariance=_covariance(pose_covariance)),
        twist=types("geometry_msgs/msg/TwistWithCovariance")(twist=twist,
                                                             covariance=_covariance(twist_covariance)))


def tf_message(types: MessageTypes, head: Any, child_frame: str, T_parent_child: np.ndarray) -> Any:
    """tf2_msgs/TFMessage with one TransformStamped: ``child_frame`` in the header's frame."""
    transform = types("geometry_msgs/msg/Transform")(
        translation=_vector3(types, np.asarray(T_parent_child, dtype=np.float64)[:3, 3]),
        rotation=_quaternion(types, T_parent_child))
    stamped = types("geometry_msgs/msg/TransformStamped")(header=head, child_frame_id=child_frame,
                                                          transform=transform)
    return types("tf2_msgs/msg/TFMessage")(transforms=[stamped])
