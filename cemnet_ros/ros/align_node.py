"""``align_node``: CEMNet point cloud alignment as a ROS 2 odometry node.

Callbacks only decode and queue; one worker thread loads the engine (so that the subscriptions exist at once
and early scans wait in the queue), then runs :class:`~cemnet_ros.pipeline.aligner.ScanAligner` and publishes.
A full queue drops its oldest scan, counted and reported.

Modes: ``sequential`` registers each ``input_topic`` scan against a local map (odometry of ``base_frame`` in
``odom_frame``); ``pair`` aligns each ``source_topic`` scan to the ``target_topic`` cloud nearest in stamp (or
the latest one, e.g. a latched map, when ``pair_tolerance`` is 0). Parameters: :mod:`.node_config`; see
docs/node.md.
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import PointCloud2, PointField
from std_srvs.srv import Trigger

from cemnet_ros.pipeline.extrinsic import BaseFrame, pose_from_xyz_rpy, pose_msg_to_matrix
from cemnet_ros.pipeline.node_status import NodeStatus
from cemnet_ros.pipeline.odometry_output import odometry_output
from cemnet_ros.pipeline.pairing import PairMatcher
from cemnet_ros.pipeline.worker import BoundedWorker
from cemnet_ros.pointcloud2 import CloudError, decode_point_times, decode_xyz, make_pointcloud2
from cemnet_ros.ros import messages
from cemnet_ros.ros.node_config import configs_from_parameters, node_parameters
from cemnet_ros.schema import values as config_values

try:  # a full ROS install, or scripts/build_tf2_msgs.sh on the pip wheels
    from tf2_msgs.msg import TFMessage
except ImportError:  # pragma: no cover - depends on the installation
    TFMessage = None
try:  # a full ROS install only: the sensor's extrinsic from TF
    import tf2_ros
except ImportError:  # pragma: no cover
    tf2_ros = None

WARN_PERIOD_S = 5.0


@dataclass
class Scan:
    """A decoded cloud waiting for the worker."""

    msg: PointCloud2
    points: np.ndarray
    times: Optional[np.ndarray]  # per-point seconds relative to the stamp, None without a time field
    stamp_ns: int


def _descriptor(p: Any) -> ParameterDescriptor:
    descriptor = ParameterDescriptor(description=p.describe(), read_only=True)
    if p.low is not None or p.high is not None:
        low, high = (-1e300 if p.low is None else p.low), (1e300 if p.high is None else p.high)
        if p.kind is int:
            descriptor.integer_range = [IntegerRange(from_value=int(low), to_value=int(min(high, 2 ** 31 - 1)), step=1)]
        elif p.kind is float:
            descriptor.floating_point_range = [FloatingPointRange(from_value=float(low), to_value=float(high))]
    if p.choices:
        descriptor.additional_constraints = "one of: " + ", ".join(p.choices)
    return descriptor


class AlignNode(Node):
    """Subscribes PointCloud2; publishes odometry, pose, TF, optional aligned cloud and map, diagnostics."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("align_node", **kwargs)
        schema = node_parameters()
        for name, p in schema.items():
            self.declare_parameter(name, list(p.default) if p.kind is tuple else p.default, _descriptor(p))
        cfg, self._pipeline_config = configs_from_parameters({n: self.get_parameter(n).value for n in schema})
        self._cfg = cfg
        self.get_logger().info("parameters in force: " + ", ".join(
            f"{k}={v}" for k, v in {**config_values(cfg), **config_values(self._pipeline_config)}.items()))
        self._base = BaseFrame(pose_from_xyz_rpy(cfg.base_to_sensor))
        self._extrinsic_from_tf = tf2_ros is not None
        self._status = NodeStatus(cfg.input_timeout)
        self._aligner: Any = None
        self._engine_ready = threading.Event()  # set when loaded, or when loading failed / the node closes
        self._engine_error: Optional[BaseException] = None
        self._map_lock = threading.Lock()  # the worker changes the map; services and timers read it
        self._last_warn: dict = {}
        self._last_stamp_ns: Optional[int] = None
        self._requests: dict[str, Any] = {}
        self._lock = threading.Lock()

        self._pose_pub = self.create_publisher(PoseStamped, "~/pose", 10)
        self._odom_pub = self.create_publisher(Odometry, "~/odometry", 10)
        self._cloud_pub = self.create_publisher(PointCloud2, "~/aligned_cloud", 10) if cfg.publish_aligned_cloud \
            else None
        map_qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._map_pub = self.create_publisher(PointCloud2, "~/local_map", map_qos)
        self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._tf_pub = self.create_publisher(TFMessage, "/tf", 100) if TFMessage is not None and cfg.publish_tf \
            else None
        if cfg.publish_tf and TFMessage is None:
            self.get_logger().warn("tf2_msgs is not importable: /tf is not published (pip install: run "
                                   "scripts/build_tf2_msgs.sh; a full ROS install has it)")
        if self._extrinsic_from_tf:
            self._tf_buffer = tf2_ros.Buffer()
            self._tf_listener = tf2_ros.TransformListener(self._tf_buffer, self)

        reliability = ReliabilityPolicy.BEST_EFFORT if cfg.qos_reliability == "best_effort" \
            else ReliabilityPolicy.RELIABLE
        input_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=cfg.qos_depth, reliability=reliability,
                               durability=DurabilityPolicy.VOLATILE)
        self._worker = BoundedWorker(self._process, maxsize=cfg.queue_size, on_error=self._on_worker_error,
                                     name="cemnet_align")
        threading.Thread(target=self._load, name="cemnet_load", daemon=True).start()
        if cfg.mode == "sequential":
            self.create_subscription(PointCloud2, cfg.input_topic, self._on_scan, input_qos)
        else:
            target_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=cfg.qos_depth,
                                    reliability=ReliabilityPolicy.RELIABLE,
                                    durability=DurabilityPolicy.TRANSIENT_LOCAL) if cfg.target_transient_local \
                else input_qos
            self._pairs: PairMatcher = PairMatcher(int(cfg.pair_tolerance * 1e9), cfg.qos_depth, cfg.qos_depth)
            self.create_subscription(PointCloud2, cfg.source_topic, self._on_source, input_qos)
            self.create_subscription(PointCloud2, cfg.target_topic, self._on_target, target_qos)
        self.create_subscription(PoseWithCovarianceStamped, "~/set_pose", self._on_set_pose, 10)
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.create_service(Trigger, "~/relocalize", self._on_relocalize)
        self.create_service(Trigger, "~/save_map", self._on_save_map)
        self.create_timer(1.0, self._publish_diagnostics)
        if cfg.local_map_period > 0:
            self.create_timer(cfg.local_map_period, self._publish_local_map)
        self.get_logger().info(f"align_node subscribed ({cfg.mode} mode); loading the engine")

    # -- inputs (executor thread: decode + enqueue only) -----------------------------------------------------
    def _decode(self, msg: PointCloud2, topic_kind: str) -> Optional[Scan]:
        self._status.input_arrived()
        try:
            points, _ = decode_xyz(msg)
            times = decode_point_times(msg) if self._pipeline_config.preprocess.deskew else None
        except CloudError as exc:
            if exc.kind != "time_field":
                self._reject(exc.kind, f"{topic_kind} cloud rejected: {exc}")
                return None
            self._warn_throttled("time_field", f"{topic_kind} cloud not deskewed: {exc}")
            times = None
        except Exception as exc:  # noqa: BLE001 - a malformed message must not take the executor down
            self._reject("invalid", f"{topic_kind} cloud rejected: {type(exc).__name__}: {exc}")
            return None
        min_points = self._pipeline_config.preprocess.min_points
        if len(points) < min_points:
            self._reject("too_few_points", f"{topic_kind} cloud rejected: {len(points)} finite points, "
                                           f"need {min_points}")
            return None
        stamp_ns = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
        return Scan(msg, points, times, stamp_ns)

    def _on_scan(self, msg: PointCloud2) -> None:
        scan = self._decode(msg, "input")
        if scan is not None:
            self._submit(scan)

    def _on_target(self, msg: PointCloud2) -> None:
        scan = self._decode(msg, "target")
        if scan is not None:
            self._queue_pairs(*self._pairs.add_target(scan))

    def _on_source(self, msg: PointCloud2) -> None:
        scan = self._decode(msg, "source")
        if scan is not None:
            self._queue_pairs(*self._pairs.add_source(scan))

    def _queue_pairs(self, ready: list, unpaired: list) -> None:
        tolerance = self._pairs.tolerance_ns * 1e-9
        for source in unpaired:
            self._reject("unpaired", f"source at {source.stamp_ns * 1e-9:.3f} s has no target within {tolerance:.3f} s")
        for pair in ready:
            self._submit(pair)

    def _submit(self, item: Any) -> None:
        if not self._worker.submit(item):
            loading = "" if self._status.ready else " while the engine loads"
            self._warn_throttled("drop", f"queue full{loading}: the oldest scan was dropped "
                                         f"({self._worker.stats().drops} so far; queue_size {self._cfg.queue_size})")

    def _reject(self, kind: str, message: str) -> None:
        count = self._status.reject(kind)
        self._warn_throttled(kind, f"[{kind}] {message} ({count} rejected so far)")

    def _request(self, name: str, value: Any, response: Optional[Trigger.Response], message: str) -> Any:
        """A request carried out by the worker before its next scan."""
        with self._lock:
            self._requests[name] = value
        self.get_logger().info(message)
        if response is not None:
            response.success, response.message = True, message
        return response

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        return self._request("reset", True, response, "reset: the map and motion model restart at the next scan; "
                             "the pose is kept (odom stays continuous)")

    def _on_relocalize(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        return self._request("relocalize", True, response,
                             "relocalize: the next scan runs the global search against the local map")

    def _on_set_pose(self, msg: PoseWithCovarianceStamped) -> None:
        frame = msg.header.frame_id
        if frame and frame != self._cfg.odom_frame:
            self._warn_throttled("set_pose", f"set_pose ignored: given in {frame!r}, not in {self._cfg.odom_frame!r}")
            return
        try:
            T = pose_msg_to_matrix(msg.pose.pose)
        except ValueError as exc:
            self._warn_throttled("set_pose", f"set_pose ignored: {exc}")
            return
        p = msg.pose.pose.position
        message = (f"set_pose: the next scan starts a new map at x={p.x:.3f} y={p.y:.3f} z={p.z:.3f} in "
                   f"{self._cfg.odom_frame} (a deliberate jump)")
        if self._aligner is None:  # still loading: applied before the first scan
            self._request("set_pose", T, None, message)
            return
        with self._map_lock:  # between two scans: the worker holds the lock while it registers one
            self._aligner.reset(self._base.sensor_pose(T))
        self.get_logger().info(message)

    def _on_save_map(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        local_map = None if self._aligner is None else self._aligner.local_map
        if local_map is None or local_map.empty():
            response.success, response.message = False, "no map yet"
            return response
        from cemnet_ros.io.pointcloud_files import write_ply

        path = Path(f"cemnet_map_{time.strftime('%Y%m%d_%H%M%S')}.ply").resolve()
        points = self._map_in_odom(local_map)
        write_ply(path, points)
        response.success = True
        response.message = f"wrote {len(points)} map points ({self._cfg.odom_frame}) to {path}"
        self.get_logger().info(response.message)
        return response

    # -- worker thread ---------------------------------------------------------------------------------------
    def _process(self, item: Any) -> None:
        self._engine_ready.wait()
        if self._aligner is None:
            raise RuntimeError(f"the engine did not load: {self._engine_error}")
        with self._lock:
            requests, self._requests = self._requests, {}
        if "reset" in requests:
            self._aligner.reset(self._aligner.pose)
        if "set_pose" in requests:
            self._aligner.reset(self._base.sensor_pose(requests["set_pose"]))
        if "relocalize" in requests:
            self._aligner.request_recovery()
        from cemnet_ros.pipeline.aligner import ScanRejected

        try:
            if isinstance(item, Scan):
                source, frame = item, self._cfg.odom_frame
                self._sensor_extrinsic(item.msg.header.frame_id)
                with self._map_lock:
                    step = self._aligner.process(item.points, item.stamp_ns, item.times)
            else:
                source, target = item
                frame = target.msg.header.frame_id or self._cfg.odom_frame
                step = self._aligner.align_pair(source.points, target.points, source.stamp_ns)
        except ScanRejected as exc:
            self._reject("preprocessing", str(exc))
            return
        self._status.step_done(step)
        if not step.accepted:
            self._warn_throttled("flagged", f"step at {step.stamp_ns * 1e-9:.3f} s flagged: {step.reason}")
        dt_s = None if self._last_stamp_ns is None else (step.stamp_ns - self._last_stamp_ns) * 1e-9
        self._last_stamp_ns = step.stamp_ns
        self._publish(step, source, frame, dt_s)

    def _load(self) -> None:
        """Import torch, load the weights and compile the kernels (seconds, a thread): scans queue meanwhile."""
        start = time.monotonic()
        try:
            from cemnet_ros.pipeline.aligner import ScanAligner

            self._aligner = ScanAligner(self._pipeline_config)
        except Exception as exc:  # noqa: BLE001 - e.g. unreadable weights: reported, every scan then errors
            self._engine_error = exc
            self.get_logger().error(f"the engine did not load: {type(exc).__name__}: {exc}")
            return
        finally:
            self._engine_ready.set()
        self._status.ready = True
        drops = self._worker.stats().drops
        self.get_logger().info(f"engine ready after {time.monotonic() - start:.1f} s" +
                               (f"; {drops} scans dropped meanwhile (queue_size {self._cfg.queue_size})" if drops
                                else ""))

    def _sensor_extrinsic(self, sensor_frame: str) -> None:
        """T_base_sensor from TF once (when tf2_ros exists), else the base_to_sensor parameter stays."""
        if not self._extrinsic_from_tf or not sensor_frame or sensor_frame == self._cfg.base_frame:
            return
        try:
            tf = self._tf_buffer.lookup_transform(self._cfg.base_frame, sensor_frame, rclpy.time.Time())
        except Exception as exc:  # noqa: BLE001 - tf2 raises several lookup errors
            self._warn_throttled("extrinsic", f"no TF {self._cfg.base_frame} <- {sensor_frame} ({exc}); using "
                                              "base_to_sensor")
            return
        t, q = tf.transform.translation, tf.transform.rotation
        T = np.eye(4)
        T[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
        T[:3, 3] = (t.x, t.y, t.z)
        self._base = BaseFrame(T)
        self._extrinsic_from_tf = False
        self.get_logger().info(f"extrinsic {self._cfg.base_frame} <- {sensor_frame} from TF")

    def _publish(self, step: Any, source: Scan, frame: str, dt_s: Optional[float]) -> None:
        cfg = self._cfg
        # The numbers (base pose, motion, twist, covariances) are cemnet-replay's too: pipeline/odometry_output.py.
        out = odometry_output(step, self._base, dt_s, cfg, self._pipeline_config.health.covariance_inflation)
        T_odom_base = out.T_odom_base
        pose = PoseStamped()
        pose.header.stamp, pose.header.frame_id = source.msg.header.stamp, frame
        messages.fill_pose(pose.pose, T_odom_base)
        self._pose_pub.publish(pose)
        self._odom_pub.publish(messages.odometry(pose.header, cfg.base_frame, out))
        if self._cloud_pub is not None:
            T_odom_sensor = T_odom_base @ self._base.T_base_sensor
            if cfg.aligned_cloud_voxel > 0:
                from cemnet_ros.pipeline.preprocess import voxel_downsample

                points = voxel_downsample(source.points @ T_odom_sensor[:3, :3].T + T_odom_sensor[:3, 3],
                                          cfg.aligned_cloud_voxel)
                cloud = make_pointcloud2(PointCloud2, PointField, points, frame, source.msg.header.stamp)
            else:
                cloud = messages.transformed_cloud(source.msg, T_odom_sensor, frame)
            self._cloud_pub.publish(cloud)
        if self._tf_pub is not None:
            parent, child, T = frame, cfg.base_frame, T_odom_base
            if cfg.invert_tf:
                parent, child, T = child, parent, np.linalg.inv(T_odom_base)
            tf_header = type(pose.header)(stamp=pose.header.stamp, frame_id=parent)
            self._tf_pub.publish(TFMessage(transforms=[messages.transform(tf_header, child, T)]))

    def _map_in_odom(self, local_map: Any) -> np.ndarray:
        """The map's points (kept in the first sensor frame) in odom_frame."""
        with self._map_lock:
            points = local_map.points
        T = self._base.T_base_sensor
        return points @ T[:3, :3].T + T[:3, 3]

    def _publish_local_map(self) -> None:
        local_map = None if self._aligner is None else self._aligner.local_map
        if local_map is None or local_map.empty() or self._map_pub.get_subscription_count() == 0:
            return
        self._map_pub.publish(make_pointcloud2(PointCloud2, PointField, self._map_in_odom(local_map),
                                               self._cfg.odom_frame, self.get_clock().now().to_msg()))

    def _warn_throttled(self, kind: str, message: str) -> None:
        """Warn at most every WARN_PERIOD_S per kind: rclpy's ``throttle_duration_sec`` throttles per call site,
        which would hide a second kind of bad input behind the first."""
        now = time.monotonic()
        with self._lock:
            warn = now - self._last_warn.get(kind, -np.inf) >= WARN_PERIOD_S
            if warn:
                self._last_warn[kind] = now
        if warn:
            self.get_logger().warn(message)

    def _on_worker_error(self, item: Any, exc: BaseException) -> None:
        self._warn_throttled("error", f"registration failed: {type(exc).__name__}: {exc}")

    def _publish_diagnostics(self) -> None:
        report = self._status.report(self._worker.stats(), None if self._aligner is None else self._aligner.scale)
        status = DiagnosticStatus(name=f"{self.get_fully_qualified_name()}: alignment", hardware_id="cemnet_ros",
                                  level=bytes([report.level]), message=report.message)
        status.values = [KeyValue(key=k, value=str(v)) for k, v in report.values.items()]
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(array)

    def destroy_node(self) -> None:
        self._engine_ready.set()  # a worker waiting for the engine gives up
        self._worker.close()
        super().destroy_node()


def main(args: Optional[list] = None) -> None:
    rclpy.init(args=args)
    node = None
    try:
        node = AlignNode()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
