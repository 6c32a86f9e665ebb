"""The node's publishers: each output's numbers (computed in the pipeline) become messages here, nothing more."""
from __future__ import annotations

from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2, PointField

from cemnet_ros.pointcloud2 import make_pointcloud2, transformed_cloud
from cemnet_ros.ros import messages
from cemnet_ros.ros.node_config import NodeConfig
from cemnet_ros.ros.path_output import PathOutput
from cemnet_ros.runtime.aligner_session import StepResult
from cemnet_ros.runtime.odometry_output import aligned_points, tf_parent_child
from cemnet_ros.runtime.scan_status import ScanVerdict

try:  # a full ROS install, or scripts/build_tf2_msgs.sh on the pip wheels
    from tf2_msgs.msg import TFMessage
except ImportError:  # pragma: no cover - depends on the installation
    TFMessage = None


class NodeOutputs:
    """~/pose, ~/odometry, /tf, ~/aligned_cloud, ~/local_map (latched), ~/path, ~/scan_status and /diagnostics."""

    def __init__(self, node: Node, cfg: NodeConfig) -> None:
        self._node, self._cfg = node, cfg
        self._pose = node.create_publisher(PoseStamped, "~/pose", 10)
        self._odom = node.create_publisher(Odometry, "~/odometry", 10)
        self._cloud = node.create_publisher(PointCloud2, "~/aligned_cloud", 10) if cfg.publish_aligned_cloud \
            else None
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._map = node.create_publisher(PointCloud2, "~/local_map", latched)
        self.path = PathOutput(node, cfg.path_max_poses) if cfg.path_period > 0 else None
        self._diagnostics = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._scan_status = node.create_publisher(DiagnosticStatus, "~/scan_status", 50)
        self._tf = node.create_publisher(TFMessage, "/tf", 100) if TFMessage is not None and cfg.publish_tf \
            else None
        if cfg.publish_tf and TFMessage is None:
            node.get_logger().warn("tf2_msgs is not importable: /tf is not published (pip install: run "
                                   "scripts/build_tf2_msgs.sh; a full ROS install has it)")

    def destroy(self) -> None:
        """Destroy the publishers (a lifecycle node's deactivate)."""
        for publisher in (self._pose, self._odom, self._cloud, self._map, self._diagnostics, self._scan_status,
                          self._tf):
            if publisher is not None:
                self._node.destroy_publisher(publisher)
        if self.path is not None:
            self.path.destroy()

    def step(self, result: StepResult, source: Any, frame: str) -> None:
        """Pose, odometry, aligned cloud and TF of one step, in ``frame`` at the stamp of ``source`` (the decoded
        scan: msg + points). The numbers are cemnet-replay's too (runtime/odometry_output.py), and so are the
        fillers (cemnet_ros/pose_messages.py)."""
        cfg, out, stamp = self._cfg, result.out, source.msg.header.stamp
        head = messages.header(frame, stamp)
        pose = messages.pose_stamped(head, out.T_odom_base)
        self._pose.publish(pose)
        if self.path is not None:
            self.path.add(pose)
        self._odom.publish(messages.odometry(head, cfg.base_frame, out))
        if self._cloud is not None:
            self._cloud.publish(self._aligned_cloud(source, result.T_odom_sensor, frame))
        if self._tf is not None:
            parent, child, T = tf_parent_child(frame, cfg.base_frame, out.T_odom_base, cfg.invert_tf)
            self._tf.publish(messages.tf_message(messages.header(parent, stamp), child, T))

    def _aligned_cloud(self, source: Any, T_odom_sensor: np.ndarray, frame: str) -> PointCloud2:
        voxel = self._cfg.aligned_cloud_voxel
        if voxel <= 0:  # every field of the input kept
            return transformed_cloud(PointCloud2, source.msg, T_odom_sensor, frame)
        return make_pointcloud2(PointCloud2, PointField, aligned_points(source.points, T_odom_sensor, voxel), frame,
                                source.msg.header.stamp)

    def scan_status(self, verdict: ScanVerdict, hardware_id: str) -> None:
        """The verdict on one input message (runtime/scan_status.py); name = its stamp in ns ("" when
        unreadable)."""
        name = "" if verdict.stamp_ns is None else str(verdict.stamp_ns)
        self._scan_status.publish(_status(name, verdict.level, verdict.message, verdict.values, hardware_id))

    def wants_map(self) -> bool:
        return self._map.get_subscription_count() > 0

    def local_map(self, points_in_odom: np.ndarray) -> None:
        self._map.publish(make_pointcloud2(PointCloud2, PointField, points_in_odom, self._cfg.odom_frame,
                                           self._node.get_clock().now().to_msg()))

    def diagnostics(self, report: Any) -> None:
        """One DiagnosticStatus from a :class:`~cemnet_ros.runtime.node_status.Report`."""
        status = _status(f"{self._node.get_fully_qualified_name()}: alignment", report.level, report.message,
                         report.values, report.hardware_id)
        array = DiagnosticArray(status=[status])
        array.header.stamp = self._node.get_clock().now().to_msg()
        self._diagnostics.publish(array)


def _status(name: str, level: int, message: str, values: dict, hardware_id: str) -> DiagnosticStatus:
    """``hardware_id``: the sensor, ``<frame_id> on <input topic>`` (runtime/node_status.py)."""
    status = DiagnosticStatus(name=name, hardware_id=hardware_id, level=bytes([level]), message=message)
    status.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
    return status
