"""``align_node``: CEMNet point cloud alignment as a ROS 2 odometry node.

Callbacks only decode and queue; one worker thread runs :class:`~cemnet_ros.pipeline.aligner.ScanAligner` and
publishes, so the executor never blocks on a registration. A full queue drops its oldest scan.

Modes: ``sequential`` aligns each scan of ``input_topic`` to the previous one (odometry in ``odom_frame``);
``pair`` aligns each ``source_topic`` scan to the ``target_topic`` cloud nearest in stamp (or to the latest
one, e.g. a latched map, when ``pair_tolerance`` is 0). See docs/node.md.
"""
from __future__ import annotations

import collections
import threading
import time
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, TransformStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import PointCloud2, PointField
from std_srvs.srv import Trigger

from cemnet_ros.pipeline.aligner import AlignerConfig, AlignmentStep, ScanAligner, ScanRejected
from cemnet_ros.pipeline.params import aligner_config_from_params
from cemnet_ros.pipeline.worker import BoundedWorker
from cemnet_ros.pointcloud2 import CloudError, decode_xyz, make_pointcloud2

try:  # tf2_msgs ships with a full ROS install, not with the pip wheels
    from tf2_msgs.msg import TFMessage
except ImportError:  # pragma: no cover - depends on the installation
    TFMessage = None

MODES = ("sequential", "pair")
RELIABILITIES = ("best_effort", "reliable")
WARN_PERIOD_S = 5.0


@dataclass
class Scan:
    """A decoded cloud waiting for the worker."""

    points: np.ndarray
    stamp: Any  # builtin_interfaces/Time, copied to every output
    stamp_ns: int
    frame_id: str


def _float_range(low: float, high: float) -> list:
    return [FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)]


def _int_range(low: int, high: int) -> list:
    return [IntegerRange(from_value=low, to_value=high, step=1)]


_DEFAULTS = AlignerConfig()  # the pipeline's defaults are the node's: one source of truth
_CEM = _DEFAULTS.registration.cem

# name: (default, description, range or None). Types follow the defaults.
PARAMETERS = {
    "mode": ("sequential", "'sequential' (scan-to-map odometry) or 'pair' (source to target topic)", None),
    "input_topic": ("points", "PointCloud2 input of sequential mode", None),
    "source_topic": ("source", "PointCloud2 source of pair mode", None),
    "target_topic": ("target", "PointCloud2 target of pair mode (subscribed TRANSIENT_LOCAL by default)", None),
    "target_transient_local": (True, "pair mode: subscribe the target RELIABLE + TRANSIENT_LOCAL (a latched map); "
                                     "false = same QoS as the source", None),
    "pair_tolerance": (0.05, "pair mode: max |stamp difference| in s; 0 = always use the latest target",
                       _float_range(0.0, 3600.0)),
    "odom_frame": ("odom", "parent frame of the pose, odometry and TF (sequential mode)", None),
    "base_frame": ("base_link", "child frame of odometry and TF; the estimated motion is the cloud frame's", None),
    "qos_reliability": ("best_effort", "input QoS reliability: 'best_effort' (sensor data) or 'reliable'", None),
    "qos_depth": (5, "input QoS history depth", _int_range(1, 1000)),
    "queue_size": (2, "scans waiting for the worker; when full the oldest is dropped", _int_range(1, 100)),
    "prior": (_DEFAULTS.prior, "CEM initial distribution: 'motion' (constant velocity), 'network' or 'identity'", None),
    "initial_rotation": (_DEFAULTS.adaptive.initial_rotation, "tracking CEM spread of the rotations (rad) until "
                         "prediction errors have been observed (then adaptive)", _float_range(1e-4, 3.2)),
    "initial_translation": (_DEFAULTS.adaptive.initial_translation, "tracking CEM spread of the translation (m) "
                            "until prediction errors have been observed (then adaptive)", _float_range(1e-4, 1000.0)),
    "identity_sigma": (_DEFAULTS.identity_sigma, "identity prior spread (rad and network units)", _float_range(1e-4, 10.0)),
    "scale": (_DEFAULTS.scale, "metres per network unit; 0 = auto (robust radius of the first target cloud)",
              _float_range(0.0, 10000.0)),
    "voxel_size": (_DEFAULTS.voxel_size, "voxel grid size (m); 0 = auto (scale / 100), negative = no voxel grid",
                   _float_range(-1.0, 1000.0)),
    "min_range": (_DEFAULTS.min_range, "drop points closer than this to the sensor (m); 0 = off", _float_range(0.0, 10000.0)),
    "max_range": (_DEFAULTS.max_range, "drop points farther than this from the sensor (m); 0 = off", _float_range(0.0, 10000.0)),
    "n_points": (_DEFAULTS.registration.n_points, "points per cloud fed to the network and the CEM", _int_range(32, 100000)),
    "n_candidates": (_CEM.n_candidates, "CEM candidates per iteration", _int_range(2, 100000)),
    "n_iters": (_CEM.n_iters, "CEM iterations", _int_range(1, 1000)),
    "n_fused_iters": (_CEM.n_fused_iters, "CEM iterations fusing the after-ICP ('future') reward (paper: 3)",
                      _int_range(0, 1000)),
    "epsilon": (_CEM.epsilon, "max-consensus truncation distance (network units)", _float_range(1e-4, 10.0)),
    "refine_iters": (_DEFAULTS.refine_iters, "point-to-plane polish iterations against the map (at most)",
                     _int_range(1, 100)),
    "refine_points": (_DEFAULTS.refine_points, "source points the polish uses at most (seeded subset)",
                      _int_range(10, 10_000_000)),
    "min_fitness": (_DEFAULTS.health.min_fitness, "inlier fraction after the polish below which a step is flagged "
                    "(the motion prediction is published, the global search runs next)", _float_range(0.0, 0.99)),
    "min_conditioning": (_DEFAULTS.health.min_conditioning, "smallest/largest eigenvalue of the polish's normalised "
                         "Hessian below which a step is degenerate (flagged, prediction kept along the free "
                         "direction)", _float_range(0.0, 0.99)),
    "recovery_radius": (_DEFAULTS.recovery.recovery_radius, "global search: translation radius (m) around the "
                        "prediction; yaw is searched over the full circle", _float_range(0.0, 1000.0)),
    "recovery_gap": (_DEFAULTS.recovery.recovery_gap, "a stamp gap longer than this (s) triggers the global search",
                     _float_range(1e-3, 3600.0)),
    "time_budget_s": (_DEFAULTS.recovery.search.time_budget_s, "global search: time budget (s) of its coarse "
                      "scoring (the scatter stops at 50 %, the resampling at 75 % of it)", _float_range(0.01, 60.0)),
    "weights": ("", "sampling network weights (.npz, or an official .pth with allow_pickle); '' = package weights",
                None),
    "allow_pickle": (False, "allow loading pickled (.pth) weights: only for files you trust", None),
    "device": ("auto", "torch device: 'auto', 'cpu', 'cuda', 'cuda:1', ...", None),
}


def _choice(name: str, value: str, choices: tuple) -> str:
    if value not in choices:
        raise ValueError(f"parameter {name} must be one of {choices}, not {value!r}")
    return value


def _pose_fields(pose_msg: Any, transform: np.ndarray) -> None:
    """Fill a geometry_msgs/Pose from a 4x4 transform."""
    pose_msg.position.x, pose_msg.position.y, pose_msg.position.z = (float(v) for v in transform[:3, 3])
    qx, qy, qz, qw = Rotation.from_matrix(transform[:3, :3]).as_quat()
    pose_msg.orientation.x, pose_msg.orientation.y = float(qx), float(qy)
    pose_msg.orientation.z, pose_msg.orientation.w = float(qz), float(qw)


class AlignNode(Node):
    """Subscribes PointCloud2, publishes pose, odometry, aligned cloud, TF and diagnostics."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("align_node", **kwargs)
        for name, (default, description, value_range) in PARAMETERS.items():
            descriptor = ParameterDescriptor(description=description, read_only=True)
            if value_range is not None and isinstance(default, float):
                descriptor.floating_point_range = value_range
            elif value_range is not None:
                descriptor.integer_range = value_range
            self.declare_parameter(name, default, descriptor)
        p = {name: self.get_parameter(name).value for name in PARAMETERS}
        self._mode = _choice("mode", p["mode"], MODES)
        _choice("qos_reliability", p["qos_reliability"], RELIABILITIES)
        self._odom_frame, self._base_frame = p["odom_frame"], p["base_frame"]
        self._pair_tolerance_ns = int(p["pair_tolerance"] * 1e9)
        self._config = aligner_config_from_params(p)  # validates prior & co.; node-only names are ignored there
        self._aligner = ScanAligner(self._config)

        self._lock = threading.Lock()  # counters and pairing buffers
        self._rejected: collections.Counter = collections.Counter()
        self._flagged = 0
        self._recoveries = 0
        self._last_warn: dict = {}
        self._last_step: Optional[AlignmentStep] = None
        self._last_stamp_ns: Optional[int] = None
        self._last_diag = (0, 0, 0, 0)  # rejected, drops, errors, flagged at the previous report
        self._reset_requested = threading.Event()
        self._relocalize_requested = threading.Event()

        self._pose_pub = self.create_publisher(PoseStamped, "~/pose", 10)
        self._odom_pub = self.create_publisher(Odometry, "~/odometry", 10)
        self._cloud_pub = self.create_publisher(PointCloud2, "~/aligned_cloud", 10)
        self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._tf_pub = self.create_publisher(TFMessage, "/tf", 100) if TFMessage is not None else None
        if self._tf_pub is None:
            self.get_logger().info("tf2_msgs is not importable: the odom->base TF is not published")

        reliability = (ReliabilityPolicy.BEST_EFFORT if p["qos_reliability"] == "best_effort"
                       else ReliabilityPolicy.RELIABLE)
        input_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=p["qos_depth"], reliability=reliability,
                               durability=DurabilityPolicy.VOLATILE)
        if self._mode == "sequential":
            self.create_subscription(PointCloud2, p["input_topic"], self._on_scan, input_qos)
        else:
            target_qos = input_qos
            if p["target_transient_local"]:
                target_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=p["qos_depth"],
                                        reliability=ReliabilityPolicy.RELIABLE,
                                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
            self._sources: collections.deque = collections.deque()
            self._targets: collections.deque = collections.deque(maxlen=max(p["qos_depth"], 1))
            self._pending_limit = p["qos_depth"]
            self.create_subscription(PointCloud2, p["source_topic"], self._on_source, input_qos)
            self.create_subscription(PointCloud2, p["target_topic"], self._on_target, target_qos)
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.create_service(Trigger, "~/relocalize", self._on_relocalize)
        self.create_timer(1.0, self._publish_diagnostics)
        self._worker = BoundedWorker(self._process, maxsize=p["queue_size"], on_error=self._on_worker_error,
                                     name="cemnet_align")
        self.get_logger().info(f"align_node ready: mode={self._mode}, prior={self._config.prior}, "
                               f"n_points={p['n_points']}, n_candidates={p['n_candidates']}, n_iters={p['n_iters']}")

    # -- inputs (executor thread: decode + enqueue only) -----------------------------------------------------
    def _decode(self, msg: PointCloud2, topic_kind: str) -> Optional[Scan]:
        try:
            points, _ = decode_xyz(msg)
        except CloudError as exc:
            self._reject(exc.kind, f"{topic_kind} cloud rejected: {exc}")
            return None
        except Exception as exc:  # noqa: BLE001 - a malformed message must not take the executor down
            self._reject("invalid", f"{topic_kind} cloud rejected: {type(exc).__name__}: {exc}")
            return None
        if len(points) < self._config.min_points:
            self._reject("too_few_points", f"{topic_kind} cloud rejected: {len(points)} finite points, "
                                           f"need {self._config.min_points}")
            return None
        stamp_ns = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
        return Scan(points, msg.header.stamp, stamp_ns, msg.header.frame_id)

    def _on_scan(self, msg: PointCloud2) -> None:
        scan = self._decode(msg, "input")
        if scan is not None:
            self._worker.submit(scan)

    def _on_target(self, msg: PointCloud2) -> None:
        scan = self._decode(msg, "target")
        if scan is not None:
            with self._lock:
                self._targets.append(scan)
            self._match_pairs()

    def _on_source(self, msg: PointCloud2) -> None:
        scan = self._decode(msg, "source")
        if scan is not None:
            with self._lock:
                self._sources.append(scan)
            self._match_pairs()

    def _match_pairs(self) -> None:
        """Queue every pending source that has a target within tolerance; give up on hopeless ones."""
        ready, unpaired = [], []
        with self._lock:
            for source in list(self._sources):
                target = self._nearest_target(source.stamp_ns)
                if target is not None:
                    ready.append((source, target))
                    self._sources.remove(source)
                elif self._targets and self._targets[-1].stamp_ns > source.stamp_ns + self._pair_tolerance_ns:
                    unpaired.append(source)
                    self._sources.remove(source)
            while len(self._sources) > self._pending_limit:
                unpaired.append(self._sources.popleft())
        for source in unpaired:
            self._reject("unpaired", f"source at {source.stamp_ns * 1e-9:.3f} s has no target within "
                                     f"{self._pair_tolerance_ns * 1e-9:.3f} s")
        for pair in ready:
            self._worker.submit(pair)

    def _nearest_target(self, stamp_ns: int) -> Optional[Scan]:
        if not self._targets:
            return None
        if self._pair_tolerance_ns == 0:
            return self._targets[-1]
        best = min(self._targets, key=lambda t: abs(t.stamp_ns - stamp_ns))
        return best if abs(best.stamp_ns - stamp_ns) <= self._pair_tolerance_ns else None

    def _reject(self, kind: str, message: str) -> None:
        """Count a rejected input and warn at most every WARN_PERIOD_S per kind."""
        with self._lock:
            self._rejected[kind] += 1
            count = self._rejected[kind]
        self._warn_throttled(kind, f"[{kind}] {message} ({count} rejected so far)")

    # -- worker thread ---------------------------------------------------------------------------------------
    def _process(self, item: Any) -> None:
        if self._reset_requested.is_set():
            self._reset_requested.clear()
            self._aligner.reset()
            self._last_stamp_ns = None
        if self._relocalize_requested.is_set():
            self._relocalize_requested.clear()
            self._aligner.request_recovery()
        try:
            if isinstance(item, Scan):
                source, frame = item, self._odom_frame
                step = self._aligner.process(item.points, item.stamp_ns)
            else:
                source, target = item
                frame = target.frame_id or self._odom_frame
                step = self._aligner.align_pair(source.points, target.points, source.stamp_ns)
        except ScanRejected as exc:
            self._reject("preprocessing", str(exc))
            return
        with self._lock:
            self._recoveries += int(step.recovered)
        if not step.accepted:
            with self._lock:
                self._flagged += 1
            self._warn_throttled("flagged", f"step at {step.stamp_ns * 1e-9:.3f} s flagged: {step.reason}")
        dt_s = None if self._last_stamp_ns is None else (step.stamp_ns - self._last_stamp_ns) * 1e-9
        self._last_stamp_ns = step.stamp_ns
        self._last_step = step
        self._publish(step, source, frame, dt_s)

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

    def _publish(self, step: AlignmentStep, source: Scan, frame: str, dt_s: Optional[float]) -> None:
        pose = PoseStamped()
        pose.header.stamp, pose.header.frame_id = source.stamp, frame
        _pose_fields(pose.pose, step.pose)
        self._pose_pub.publish(pose)

        odom = Odometry()
        odom.header = pose.header
        odom.child_frame_id = self._base_frame
        odom.pose.pose = pose.pose
        odom.pose.covariance = [float(v) for v in step.covariance.reshape(-1)]
        if step.relative is not None and dt_s is not None and dt_s > 0:
            linear = step.relative[:3, 3] / dt_s
            angular = Rotation.from_matrix(step.relative[:3, :3]).as_rotvec() / dt_s
            t = odom.twist.twist
            t.linear.x, t.linear.y, t.linear.z = (float(v) for v in linear)
            t.angular.x, t.angular.y, t.angular.z = (float(v) for v in angular)
            odom.twist.covariance = [float(v) for v in (step.covariance / dt_s ** 2).reshape(-1)]
        self._odom_pub.publish(odom)

        aligned = source.points @ step.pose[:3, :3].T + step.pose[:3, 3]
        self._cloud_pub.publish(make_pointcloud2(PointCloud2, PointField, aligned, frame, source.stamp))

        if self._tf_pub is not None:
            tf = TransformStamped()
            tf.header = pose.header
            tf.child_frame_id = self._base_frame
            p, q = pose.pose.position, pose.pose.orientation
            tf.transform.translation.x, tf.transform.translation.y, tf.transform.translation.z = p.x, p.y, p.z
            tf.transform.rotation = q
            self._tf_pub.publish(TFMessage(transforms=[tf]))

    # -- service and diagnostics ---------------------------------------------------------------------------
    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        return self._request(self._reset_requested, response,
                             "reset: the next scan starts a new trajectory at the identity pose")

    def _on_relocalize(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        return self._request(self._relocalize_requested, response,
                             "relocalize: the next scan runs the global search against the local map")

    def _request(self, event: threading.Event, response: Trigger.Response, message: str) -> Trigger.Response:
        """A service's request, carried out by the worker before its next scan."""
        event.set()
        response.success, response.message = True, message
        self.get_logger().info(message)
        return response

    def _publish_diagnostics(self) -> None:
        stats = self._worker.stats()
        step = self._last_step
        with self._lock:
            rejected = dict(self._rejected)
            flagged = self._flagged
        total_rejected = sum(rejected.values())
        previous = self._last_diag
        self._last_diag = (total_rejected, stats.drops, stats.errors, flagged)
        status = DiagnosticStatus(name=f"{self.get_fully_qualified_name()}: alignment", hardware_id="cemnet_ros")
        problems = [label for label, now, before in (("rejected inputs", total_rejected, previous[0]),
                                                     ("dropped scans", stats.drops, previous[1]),
                                                     ("registration errors", stats.errors, previous[2]),
                                                     ("flagged steps", flagged, previous[3])) if now > before]
        status.level = DiagnosticStatus.WARN if problems else DiagnosticStatus.OK
        status.message = ("new " + ", ".join(problems)) if problems else "ok"
        values = {
            "queue_depth": stats.depth, "queue_drops": stats.drops, "processed": stats.processed,
            "errors": stats.errors, "latency_last_ms": round(stats.latency_last_s * 1e3, 1),
            "latency_mean_ms": round(stats.latency_mean_s * 1e3, 1),
            "latency_max_ms": round(stats.latency_max_s * 1e3, 1),
            "last_fitness": "" if step is None else round(step.fitness, 4),
            "last_accepted": "" if step is None else step.accepted,
            "last_reason": "" if step is None else step.reason,
            "last_recovered": "" if step is None else step.recovered,
            "last_recovery_reason": "" if step is None else step.recovery_reason,
            "last_degenerate": "" if step is None else step.degenerate,
            "recoveries": self._recoveries,
            "flagged_steps": flagged, "rejected_inputs": total_rejected,
            "scale_m_per_unit": "" if self._aligner.scale is None else round(self._aligner.scale, 4),
        }
        values.update({f"rejected_{kind}": count for kind, count in sorted(rejected.items())})
        status.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(array)

    def destroy_node(self) -> None:
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
