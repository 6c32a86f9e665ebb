"""The DDS test harness of align_node: an align_node and a probe node in one process, the street scans."""
from __future__ import annotations

import os
import threading
import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # read when the DDS participant is created

import rclpy  # noqa: E402
from builtin_interfaces.msg import Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from geometry_msgs.msg import PoseStamped, Quaternion, TransformStamped, Vector3  # noqa: E402
from nav_msgs.msg import Odometry  # noqa: E402
from rcl_interfaces.msg import Log  # noqa: E402
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import PointCloud2, PointField  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402
from street_scene import make_transform, make_world, street_scan  # noqa: E402

from cemnet_ros.pointcloud2 import make_pointcloud2  # noqa: E402
from cemnet_ros.ros.align_node import AlignNode  # noqa: E402
from cemnet_ros.ros.outputs import TFMessage  # noqa: E402
from cemnet_ros.runtime.extrinsic import pose_from_xyz_rpy  # noqa: E402

HARNESS_PARAMETERS = {"qos_reliability": "reliable", "queue_size": 10, "publish_aligned_cloud": True}
FIRST_TIMEOUT = 120.0  # the first registration loads the engine (a cold machine, a busy one: minutes)

WORLD = make_world()
EXTRINSIC = (0.3, -0.1, 1.7, 0.01, -0.02, 0.5)  # a sensor's pose on the base (x y z roll pitch yaw)
POSES = [make_transform(yaw=0.02 * k, t=(0.5 * k, 0.05 * k, 0.0)) for k in range(6)]


def scan_msg(k, pose=None, n=12000, frame="lidar"):
    rng = np.random.default_rng(100 + k)
    pose = POSES[k] if pose is None else pose
    return make_pointcloud2(PointCloud2, PointField, street_scan(WORLD, pose, rng, n), frame, stamp(k))


def stamp(k):
    ns = 1_000_000_000 + k * 100_000_000
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def pose_of(msg):
    """4x4 pose of an Odometry or PoseStamped message."""
    pose = msg.pose.pose if isinstance(msg, Odometry) else msg.pose
    q, p = pose.orientation, pose.position
    out = np.eye(4)
    out[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    out[:3, 3] = [p.x, p.y, p.z]
    return out




class StandInBuffer:
    """tf2_ros.Buffer's lookup_transform: raises until :attr:`transform` is set (TF not up yet)."""

    def __init__(self):
        self.transform = None

    def lookup_transform(self, target, source, _time):
        if self.transform is None:
            raise LookupError(f"{target} <- {source}: no transform yet")
        return self.transform


def transform(xyz_rpy):
    """A TransformStamped of (x, y, z, roll, pitch, yaw), as a TF lookup returns it."""
    T = pose_from_xyz_rpy(xyz_rpy)
    msg = TransformStamped()
    msg.transform.translation = Vector3(x=T[0, 3], y=T[1, 3], z=T[2, 3])
    x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
    msg.transform.rotation = Quaternion(x=x, y=y, z=z, w=w)
    return msg


def wait_for(predicate, timeout):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return predicate()


class Harness:
    """An align_node plus a probe node (publishers, subscribers, reset client) spinning in one background thread."""

    def __init__(self, context, namespace, overrides, input_topics=("points",), target_latched=None):
        params = [Parameter(k, value=v) for k, v in {**HARNESS_PARAMETERS, **overrides}.items()]
        self.node = AlignNode(context=context, namespace=namespace, parameter_overrides=params)
        self.probe = rclpy.create_node("probe", namespace=namespace, context=context)
        self.odometry, self.poses, self.clouds, self.diagnostics, self.logs, self.tfs = [], [], [], [], [], []
        self.statuses = []  # ~/scan_status: one verdict per input message
        self.namespace = namespace
        ns = f"/{namespace}/align_node"
        self.probe.create_subscription(Odometry, f"{ns}/odometry", self.odometry.append, 50)
        self.probe.create_subscription(PoseStamped, f"{ns}/pose", self.poses.append, 50)
        self.probe.create_subscription(DiagnosticStatus, f"{ns}/scan_status", self.statuses.append, 200)
        self.probe.create_subscription(PointCloud2, f"{ns}/aligned_cloud", self.clouds.append, 50)
        self.probe.create_subscription(DiagnosticArray, "/diagnostics", self._on_diag, 50)
        self.probe.create_subscription(Log, "/rosout", self._on_log, 100)
        if TFMessage is not None:
            self.probe.create_subscription(TFMessage, "/tf", self.tfs.append, 100)
        self.pubs = {t: self.probe.create_publisher(PointCloud2, f"/{namespace}/{t}", 10) for t in input_topics}
        if target_latched is not None:
            qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
            self.pubs[target_latched] = self.probe.create_publisher(PointCloud2, f"/{namespace}/{target_latched}",
                                                                    qos)
        self.reset_client = self.probe.create_client(Trigger, f"{ns}/reset")
        self.name = f"{ns}: alignment"
        self.executor = MultiThreadedExecutor(num_threads=2, context=context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.probe)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()
        for topic, pub in self.pubs.items():
            assert wait_for(lambda: pub.get_subscription_count() > 0, 10.0), f"node never subscribed {topic}"

    def _on_diag(self, msg):
        self.diagnostics.extend(s for s in msg.status if s.name == self.name)

    def _on_log(self, msg):
        if msg.name.endswith("align_node"):
            self.logs.append(msg)

    def values(self):
        return {kv.key: kv.value for kv in self.diagnostics[-1].values} if self.diagnostics else {}

    def send(self, msg, topic="points", timeout=60.0, expect_output=True):
        """Publish ``msg``; wait for its odometry (or just give the node time when no output is expected)."""
        count = len(self.odometry)
        self.pubs[topic].publish(msg)
        if expect_output:
            assert wait_for(lambda: len(self.odometry) > count, timeout), "no odometry output"
            return self.odometry[-1]
        return None

    def close(self):
        self.executor.shutdown()
        self.thread.join(10)
        self.node.destroy_node()
        self.probe.destroy_node()


def read_bag(path):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    clouds, truth = [], {}
    with AnyReader([path], default_typestore=store) as reader:
        cloud_topics = [c for c in reader.connections if c.msgtype == "sensor_msgs/msg/PointCloud2"]
        truth_topics = [c for c in reader.connections if c.msgtype == "geometry_msgs/msg/PoseStamped"
                        and c.topic.endswith("ground_truth")]
        if not cloud_topics or not truth_topics:
            pytest.skip(f"{path.name}: no PointCloud2 or ground_truth topic")
        for conn, _, raw in reader.messages(connections=cloud_topics[:1] + truth_topics[:1]):
            msg = reader.deserialize(raw, conn.msgtype)
            ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            if conn in cloud_topics:
                clouds.append((ns, bytes(raw)))
            else:
                q, p = msg.pose.orientation, msg.pose.position
                pose = np.eye(4)
                pose[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
                pose[:3, 3] = [p.x, p.y, p.z]
                truth[ns] = pose
    return clouds, truth
