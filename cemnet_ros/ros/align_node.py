"""``align_node``: CEMNet point cloud alignment as a ROS 2 odometry node.

The subscriptions take the messages' CDR bytes and only queue them (:mod:`.scans`); one worker thread loads the engine
(so that the subscriptions exist at once and early scans wait in the queue), then deserializes and decodes, checks
(:mod:`~cemnet_ros.pipeline.input_checks`), registers with :class:`~cemnet_ros.pipeline.aligner.ScanAligner`
and publishes (:mod:`.outputs`). A full queue drops its oldest message before it is deserialized, counted and reported.

Modes: ``sequential`` registers each ``input_topic`` scan against a local map (odometry of ``base_frame`` in
``odom_frame``); ``pair`` aligns each ``source_topic`` scan to the ``target_topic`` cloud nearest in stamp (or
the latest one, e.g. a latched map, when ``pair_tolerance`` is 0). Parameters: :mod:`.node_config`; see
docs/node.md.
"""
from __future__ import annotations

import sys
import threading
import time
import traceback
from pathlib import Path
from typing import Any, Optional

import numpy as np
import rclpy
from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import Trigger

from cemnet_ros.pipeline.extrinsic import BaseFrame, pose_from_xyz_rpy, pose_msg_to_matrix
from cemnet_ros.pipeline.input_checks import ScanRejected
from cemnet_ros.pipeline.node_status import NodeStatus
from cemnet_ros.pipeline.pairing import PairMatcher
from cemnet_ros.pipeline.worker import BoundedWorker
from cemnet_ros.ros.outputs import NodeOutputs
from cemnet_ros.ros.parameters import ConfigError, declare_and_read
from cemnet_ros.ros.scans import Incoming, Scan, decode
from cemnet_ros.schema import values as config_values

try:  # a full ROS install only: the sensor's extrinsic from TF
    import tf2_ros
except ImportError:  # pragma: no cover
    tf2_ros = None

WARN_PERIOD_S = 5.0


class AlignNode(Node):
    """Subscribes PointCloud2; publishes odometry, pose, TF, optional aligned cloud and map, diagnostics.

    Raises ConfigError for a parameter it cannot start with; :attr:`fatal_error` is set when the engine
    cannot load (``main`` then exits 2).
    """

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("align_node", **kwargs)
        cfg, self._pipeline_config = declare_and_read(self)
        self._cfg = cfg
        self.get_logger().info("parameters in force: " + ", ".join(
            f"{k}={v}" for k, v in {**config_values(cfg), **config_values(self._pipeline_config)}.items()))
        self.fatal_error: Optional[str] = None
        self._base = BaseFrame(pose_from_xyz_rpy(cfg.base_to_sensor))
        self._extrinsic_from_tf = tf2_ros is not None
        self._status = NodeStatus(cfg.input_timeout)
        self._aligner: Any = None
        self._engine_ready = threading.Event()  # set when loaded, or when loading failed / the node closes
        self._map_lock = threading.Lock()  # the worker changes the map; services and timers read it
        self._last_warn: dict = {}
        self._errors_logged: set[str] = set()
        self._last_stamp_ns: Optional[int] = None
        self._requests: dict[str, Any] = {}
        self._lock = threading.Lock()
        self._target: Optional[tuple[Incoming, Scan]] = None  # pair mode: the last target, decoded once

        self._outputs = NodeOutputs(self, cfg, self._pipeline_config.health.covariance_inflation)
        if self._extrinsic_from_tf:
            self._tf_buffer = tf2_ros.Buffer()
            self._tf_listener = tf2_ros.TransformListener(self._tf_buffer, self)
        self._worker = BoundedWorker(self._process, maxsize=cfg.queue_size, on_error=self._on_worker_error,
                                     name="cemnet_align")
        threading.Thread(target=self._load, name="cemnet_load", daemon=True).start()
        self._subscribe(cfg)
        self.create_subscription(PoseWithCovarianceStamped, "~/set_pose", self._on_set_pose, 10)
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.create_service(Trigger, "~/relocalize", self._on_relocalize)
        self.create_service(Trigger, "~/save_map", self._on_save_map)
        self.create_timer(1.0, self._publish_diagnostics)
        if cfg.local_map_period > 0:
            self.create_timer(cfg.local_map_period, self._publish_local_map)
        self.get_logger().info(f"align_node subscribed ({cfg.mode} mode); loading the engine")

    def _subscribe(self, cfg: Any) -> None:
        reliability = ReliabilityPolicy.BEST_EFFORT if cfg.qos_reliability == "best_effort" \
            else ReliabilityPolicy.RELIABLE
        input_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=cfg.qos_depth, reliability=reliability,
                               durability=DurabilityPolicy.VOLATILE)
        if cfg.mode == "sequential":
            self._input_topic = cfg.input_topic
            self.create_subscription(PointCloud2, cfg.input_topic, self._on_scan, input_qos, raw=True)
            return
        target_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=cfg.qos_depth,
                                reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.TRANSIENT_LOCAL) if cfg.target_transient_local \
            else input_qos
        self._pairs: PairMatcher = PairMatcher(int(cfg.pair_tolerance * 1e9), cfg.qos_depth, cfg.qos_depth)
        self._input_topic = cfg.source_topic
        self.create_subscription(PointCloud2, cfg.source_topic, self._on_source, input_qos, raw=True)
        self.create_subscription(PointCloud2, cfg.target_topic, self._on_target, target_qos, raw=True)

    # -- inputs (executor thread: CDR bytes + stamp, enqueue; no deserializing) ------------------------------
    def _incoming(self, payload: bytes, topic_kind: str) -> Optional[Incoming]:
        self._status.input_arrived()
        try:
            return Incoming.of(payload, topic_kind)
        except ScanRejected as exc:
            self._reject(exc.kind, f"{topic_kind} cloud rejected: {exc}", None)
            return None

    def _on_scan(self, payload: bytes) -> None:
        item = self._incoming(payload, "input")
        if item is not None:
            self._submit(item)

    def _on_target(self, payload: bytes) -> None:
        item = self._incoming(payload, "target")
        if item is not None:
            self._queue_pairs(*self._pairs.add_target(item))

    def _on_source(self, payload: bytes) -> None:
        item = self._incoming(payload, "source")
        if item is not None:
            self._queue_pairs(*self._pairs.add_source(item))

    def _queue_pairs(self, ready: list, unpaired: list) -> None:
        tolerance = self._pairs.tolerance_ns * 1e-9
        for source in unpaired:
            self._reject("unpaired", f"source at {source.stamp_ns * 1e-9:.3f} s has no target within {tolerance:.3f} s",
                         source.stamp_ns)
        for pair in ready:
            self._submit(pair)

    def _submit(self, item: Any) -> None:
        if not self._worker.submit(item):
            loading = "" if self._status.ready else " while the engine loads"
            self._warn_throttled("drop", f"queue full{loading}: the oldest scan was dropped "
                                         f"({self._worker.stats().drops} so far; queue_size {self._cfg.queue_size})")

    def _reject(self, kind: str, message: str, stamp_ns: Optional[int]) -> None:
        count = self._status.reject(kind)
        self._warn_throttled(kind, f"[{kind}] {message} ({count} rejected so far)")
        self._outputs.scan_status(stamp_ns, 2, message, rejected=kind)

    def _warn_all(self, warnings: list) -> None:
        for kind, message in warnings:
            count = self._status.warn(kind)
            self._warn_throttled(kind, f"[{kind}] {message} ({count} so far)")
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
            raise RuntimeError(f"the engine did not load: {self.fatal_error}")
        self._apply_requests()
        try:
            step, source, frame = self._sequential(item) if isinstance(item, Incoming) else self._pair(*item)
        except ScanRejected as exc:
            self._reject(exc.kind, str(exc), _stamp_of(item))
            return
        self._status.step_done(step)
        self._warn_all(step.warnings)
        if not step.accepted:
            self._warn_throttled("flagged", f"step at {step.stamp_ns * 1e-9:.3f} s flagged: {step.reason}")
        self._outputs.scan_status(step.stamp_ns, 0 if step.accepted else 1, step.reason or "ok",
                                  fitness=round(step.fitness, 4), recovered=step.recovered,
                                  warnings="; ".join(f"[{kind}] {text}" for kind, text in step.warnings))
        dt_s = None if self._last_stamp_ns is None else (step.stamp_ns - self._last_stamp_ns) * 1e-9
        self._last_stamp_ns = step.stamp_ns
        self._outputs.step(step, source, frame, self._base, dt_s)

    def _apply_requests(self) -> None:
        with self._lock:
            requests, self._requests = self._requests, {}
        if "reset" in requests:
            self._aligner.reset(self._aligner.pose)
        if "set_pose" in requests:
            self._aligner.reset(self._base.sensor_pose(requests["set_pose"]))
        if "relocalize" in requests:
            self._aligner.request_recovery()

    def _decode(self, item: Incoming) -> Scan:
        scan = decode(item, self._pipeline_config.preprocess.deskew,
                      lambda payload: deserialize_message(payload, PointCloud2))
        self._status.decoded()
        self._warn_all(scan.warnings)
        return scan

    def _sequential(self, item: Incoming) -> tuple[Any, Scan, str]:
        scan = self._decode(item)
        frame_id = scan.msg.header.frame_id
        self._sensor_extrinsic(frame_id)
        with self._map_lock:
            step = self._aligner.process(scan.points, scan.stamp_ns, scan.times, frame_id=frame_id,
                                         now_ns=self.get_clock().now().nanoseconds, n_total=scan.n_total)
        return step, scan, self._cfg.odom_frame

    def _pair(self, source_item: Incoming, target_item: Incoming) -> tuple[Any, Scan, str]:
        if self._target is None or self._target[0] is not target_item:  # a latched target is decoded once
            self._target = (target_item, self._decode(target_item))
        target, source = self._target[1], self._decode(source_item)
        step = self._aligner.align_pair(source.points, target.points, source.stamp_ns,
                                        source_frame=source.msg.header.frame_id,
                                        target_frame=target.msg.header.frame_id, target_stamp_ns=target.stamp_ns,
                                        now_ns=self.get_clock().now().nanoseconds, n_total=source.n_total)
        return step, source, target.msg.header.frame_id or self._cfg.odom_frame

    def _load(self) -> None:
        """Import torch, load the weights and compile the kernels (seconds, a thread): scans queue meanwhile."""
        start = time.monotonic()
        try:
            from cemnet_ros.pipeline.aligner import ScanAligner

            self._aligner = ScanAligner(self._pipeline_config)
        except Exception as exc:  # noqa: BLE001 - e.g. a corrupt weights file: fatal, main exits 2
            self.fatal_error = f"the engine did not load: {type(exc).__name__}: {str(exc).splitlines()[0]}"
            self.get_logger().error(self.fatal_error)
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

    def _map_in_odom(self, local_map: Any) -> np.ndarray:
        """The map's points (kept in the first sensor frame) in odom_frame."""
        with self._map_lock:
            points = local_map.points
        T = self._base.T_base_sensor
        return points @ T[:3, :3].T + T[:3, 3]

    def _publish_local_map(self) -> None:
        local_map = None if self._aligner is None else self._aligner.local_map
        if local_map is None or local_map.empty() or not self._outputs.wants_map():
            return
        self._outputs.local_map(self._map_in_odom(local_map))

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
        """A scan whose processing raised: counted, warned, and an ERROR verdict (no scan goes unreported)."""
        if not self.context.ok():
            return  # shutting down: the publishers are gone, nothing failed
        message = f"registration failed: {type(exc).__name__}: {exc}"
        if type(exc).__name__ not in self._errors_logged:  # the first of a kind with its traceback: a bug to report
            self._errors_logged.add(type(exc).__name__)
            self.get_logger().error(message + "\n" + "".join(traceback.format_exception(exc)))
        self._warn_throttled("error", message)
        self._outputs.scan_status(_stamp_of(item), 2, message, error=type(exc).__name__)

    def _publish_diagnostics(self) -> None:
        scale = None if self._aligner is None else self._aligner.scale
        self._outputs.diagnostics(self._status.report(self._worker.stats(), scale,
                                                      self.count_publishers(self._input_topic)))

    def destroy_node(self) -> None:
        self._engine_ready.set()  # a worker waiting for the engine gives up
        self._worker.close()
        super().destroy_node()


def _stamp_of(item: Any) -> int:
    """The stamp of a queued item: a scan (sequential mode) or a (source, target) pair (its source's)."""
    return item.stamp_ns if isinstance(item, Incoming) else item[0].stamp_ns


def main(args: Optional[list] = None) -> None:
    """Spin until SIGINT; a fatal configuration or engine error is one line on stderr and exit status 2."""
    rclpy.init(args=args)
    node, error = None, None
    try:
        node = AlignNode()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        while rclpy.ok() and node.fatal_error is None:
            executor.spin_once(timeout_sec=0.25)
        error = node.fatal_error
    except (ConfigError, ParameterException) as exc:
        error = str(exc).splitlines()[0]
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    if error:
        print(f"align_node: error: {error}", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()
