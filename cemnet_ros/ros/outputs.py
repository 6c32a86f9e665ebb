"""The node's publishers and how a step, the map and the status become messages."""
from __future__ import annotations

from typing import Any, Optional

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2, PointField

from cemnet_ros.pipeline.extrinsic import BaseFrame
from cemnet_ros.pipeline.odometry_output import odometry_output
from cemnet_ros.pointcloud2 import make_pointcloud2
from cemnet_ros.ros import messages
from cemnet_ros.ros.node_config import NodeConfig

try:  # a full ROS install, or scripts/build_tf2_msgs.sh on the pip wheels
    from tf2_msgs.msg import TFMessage
except ImportError:  # pragma: no cover - depends on the installation
    TFMessage = None


class NodeOutputs:
    """~/pose, ~/odometry, /tf, ~/aligned_cloud, ~/local_map (latched), ~/scan_status and /diagnostics."""

    def __init__(self, node: Node, cfg: NodeConfig, covariance_inflation: float) -> None:
        self._node, self._cfg, self._inflation = node, cfg, covariance_inflation
        self._pose = node.create_publisher(PoseStamped, "~/pose", 10)
        self._odom = node.create_publisher(Odometry, "~/odometry", 10)
        self._cloud = node.create_publisher(PointCloud2, "~/aligned_cloud", 10) if cfg.publish_aligned_cloud \
            else None
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._map = node.create_publisher(PointCloud2, "~/local_map", latched)
        self._diagnostics = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._scan_status = node.create_publisher(DiagnosticStatus, "~/scan_status", 50)
        self._tf = node.create_publisher(TFMessage, "/tf", 100) if TFMessage is not None and cfg.publish_tf \
            else None
        if cfg.publish_tf and TFMessage is None:
            node.get_logger().warn("tf2_msgs is not importable: /tf is not published (pip install: run "
                                   "scripts/build_tf2_msgs.sh; a full ROS install has it)")

    def step(self, step: Any, source: Any, frame: str, base: BaseFrame, dt_s: Optional[float]) -> None:
        """Pose, odometry, aligned cloud and TF of one step; ``source`` is the decoded scan (msg + points)."""
        cfg = self._cfg
        # The numbers (base pose, motion, twist, covariances) are cemnet-replay's too: pipeline/odometry_output.py.
        out = odometry_output(step, base, dt_s, cfg, self._inflation)
        pose = PoseStamped()
        pose.header.stamp, pose.header.frame_id = source.msg.header.stamp, frame
        messages.fill_pose(pose.pose, out.T_odom_base)
        self._pose.publish(pose)
        self._odom.publish(messages.odometry(pose.header, cfg.base_frame, out))
        if self._cloud is not None:
            self._cloud.publish(self._aligned_cloud(source, out.T_odom_base @ base.T_base_sensor, frame))
        if self._tf is not None:
            parent, child, T = frame, cfg.base_frame, out.T_odom_base
            if cfg.invert_tf:
                parent, child, T = child, parent, np.linalg.inv(out.T_odom_base)
            header = type(pose.header)(stamp=pose.header.stamp, frame_id=parent)
            self._tf.publish(TFMessage(transforms=[messages.transform(header, child, T)]))

    def _aligned_cloud(self, source: Any, T_odom_sensor: np.ndarray, frame: str) -> PointCloud2:
        voxel = self._cfg.aligned_cloud_voxel
        if voxel <= 0:
            return messages.transformed_cloud(source.msg, T_odom_sensor, frame)
        from cemnet_ros.pipeline.preprocess import voxel_downsample

        points = voxel_downsample(source.points @ T_odom_sensor[:3, :3].T + T_odom_sensor[:3, 3], voxel)
        return make_pointcloud2(PointCloud2, PointField, points, frame, source.msg.header.stamp)

    def scan_status(self, stamp_ns: Optional[int], level: int, message: str, **values: Any) -> None:
        """The verdict on one input message: OK (a good step), WARN (flagged, published), ERROR (rejected, with
        its kind in ``values``); name = the message's stamp in ns ("" when it could not be read)."""
        self._scan_status.publish(_status("" if stamp_ns is None else str(stamp_ns), level, message, values))

    def wants_map(self) -> bool:
        return self._map.get_subscription_count() > 0

    def local_map(self, points_in_odom: np.ndarray) -> None:
        self._map.publish(make_pointcloud2(PointCloud2, PointField, points_in_odom, self._cfg.odom_frame,
                                           self._node.get_clock().now().to_msg()))

    def diagnostics(self, report: Any) -> None:
        """One DiagnosticStatus from a :class:`~cemnet_ros.pipeline.node_status.Report`."""
        status = _status(f"{self._node.get_fully_qualified_name()}: alignment", report.level, report.message,
                         report.values)
        array = DiagnosticArray(status=[status])
        array.header.stamp = self._node.get_clock().now().to_msg()
        self._diagnostics.publish(array)


def _status(name: str, level: int, message: str, values: dict) -> DiagnosticStatus:
    status = DiagnosticStatus(name=name, hardware_id="cemnet_ros", level=bytes([level]), message=message)
    status.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
    return status
