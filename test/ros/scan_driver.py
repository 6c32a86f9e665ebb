"""A sensor driver's side over DDS, in a context of its own: publishes PointCloud2 scans to a node started as a
process (``ros2 launch``, ``ros2 run``, an installed executable) and collects its odometry."""
from __future__ import annotations

import os
import threading

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # read when the DDS participant is created

import rclpy  # noqa: E402
from builtin_interfaces.msg import Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from nav_msgs.msg import Odometry  # noqa: E402
from node_harness import wait_for  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import PointCloud2  # noqa: E402


class Driver:
    """The sensor driver's side: publishes PointCloud2 scans (messages or their CDR bytes) on ``namespace``/points
    (with ``clock``, /clock at each scan's stamp first, as a simulator or ``ros2 bag play --clock``), collects the
    node's odometry. Made once the node has subscribed: it waits until the node's diagnostics count this
    publisher."""

    def __init__(self, domain_id: int, namespace: str = "", clock: bool = False):
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node("kitti_driver", context=self.context)
        self.namespace = namespace
        self.points = self.node.create_publisher(PointCloud2, f"{namespace}/points", 10)
        self.clock = self.node.create_publisher(Clock, "/clock", 10) if clock else None
        self.odometry: list = []
        self.node.create_subscription(Odometry, f"{namespace}/align_node/odometry", self.odometry.append, 50)
        self.publishers_seen = 0  # by the node, from its diagnostics: it has matched this publisher
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 10)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()
        # Best effort (the node's default QoS) drops what is sent before both sides have matched each other.
        assert wait_for(lambda: self.points.get_subscription_count() > 0 and self.publishers_seen > 0, 30.0), \
            "align_node never subscribed"

    def _on_diagnostics(self, msg) -> None:
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if status.name.startswith(f"{self.namespace}/align_node") and values.get("input_publishers",
                                                                                       "0").isdigit():
                self.publishers_seen = max(self.publishers_seen, int(values["input_publishers"]))

    def send(self, raw: bytes, stamp_ns: int = 0):
        count = len(self.odometry)
        if self.clock is not None:
            self.clock.publish(Clock(clock=Time(sec=stamp_ns // 10 ** 9, nanosec=stamp_ns % 10 ** 9)))
        self.points.publish(raw)
        assert wait_for(lambda: len(self.odometry) > count, 120.0), "no odometry"
        return self.odometry[-1]

    def close(self):
        self.executor.shutdown()
        self.thread.join(10)
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)
