"""The shared message fillers (:mod:`cemnet_ros.pose_messages`) bound to rclpy's generated classes.

The replay's bag writer binds the same fillers to rosbags' classes, so both publish the same messages.
"""
from __future__ import annotations

import functools
import importlib
from typing import Any

import numpy as np

from cemnet_ros import pose_messages
from cemnet_ros.runtime.odometry_output import OdometryOutput


@functools.cache
def rclpy_type(name: str) -> Any:
    """The rclpy class of a full type name, e.g. ``"nav_msgs/msg/Odometry"`` -> ``nav_msgs.msg.Odometry``."""
    package, _, class_name = name.split("/")
    return getattr(importlib.import_module(f"{package}.msg"), class_name)


def header(frame_id: str, stamp: Any) -> Any:
    """std_msgs/Header with an input's builtin_interfaces/Time."""
    return pose_messages.header(rclpy_type, frame_id, stamp)


def pose_stamped(head: Any, T_frame_child: np.ndarray) -> Any:
    return pose_messages.pose_stamped(rclpy_type, head, T_frame_child)


def odometry(head: Any, child_frame: str, out: OdometryOutput) -> Any:
    """nav_msgs/Odometry of one step: the pose in the header's frame, the twist in ``child_frame`` (REP-105)."""
    return pose_messages.odometry(rclpy_type, head, child_frame, out.T_odom_base, out.pose_covariance,
                                  linear=out.linear, angular=out.angular, twist_covariance=out.twist_covariance)


def tf_message(head: Any, child_frame: str, T_parent_child: np.ndarray) -> Any:
    return pose_messages.tf_message(rclpy_type, head, child_frame, T_parent_child)
