"""The work of an align node, wired to an rclpy node: subscriptions, the worker, outputs, services, diagnostics.

The subscriptions take the messages' CDR bytes and only queue them (:mod:`.scans`, pair mode through
:class:`~cemnet_ros.runtime.pairing.PairMatcher`); one worker thread deserializes and decodes, then
registers through :class:`~cemnet_ros.runtime.aligner_session.AlignerSession` and publishes
(:mod:`.outputs`). Every input gets a verdict (:mod:`~cemnet_ros.runtime.scan_status`); a full queue drops its
oldest message before it is deserialized, counted and reported. Services: :mod:`.services`.

``align_node`` keeps one for its whole life; ``align_lifecycle_node`` makes one on ``activate`` around the session
that ``configure`` loaded and destroys it on ``deactivate`` (:meth:`Alignment.destroy`).
"""
from __future__ import annotations

import time
from typing import Any, Optional

import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import PointCloud2

from cemnet_ros.pipeline.errors import ScanRejected
from cemnet_ros.ros.node_config import NodeConfig
from cemnet_ros.ros.outputs import NodeOutputs
from cemnet_ros.ros.scans import Incoming, Scan, decode
from cemnet_ros.ros.services import NodeServices
from cemnet_ros.runtime.aligner_session import AlignerSession, StepResult
from cemnet_ros.runtime.arrival_period import ArrivalPeriod
from cemnet_ros.runtime.extrinsic import BaseFrame, transform_msg_to_matrix
from cemnet_ros.runtime.extrinsic_hold import ExtrinsicHold
from cemnet_ros.runtime.node_status import NodeStatus
from cemnet_ros.runtime.pairing import PairMatcher
from cemnet_ros.runtime.scan_status import Outcome, ScanStatus
from cemnet_ros.runtime.worker import BoundedWorker

try:  # a full ROS install only: the sensor's extrinsic from TF
    import tf2_ros
except ImportError:  # pragma: no cover
    tf2_ros = None


class Alignment:
    """Subscribes PointCloud2; publishes odometry, pose, TF, optional aligned cloud and map, diagnostics.

    ``session`` and ``extrinsic`` outlive it in a lifecycle node (the trajectory continues after a reactivation);
    :attr:`status`.ready says whether the engine has loaded (:meth:`engine_ready`).
    """

    def __init__(self, node: Node, cfg: NodeConfig, session: AlignerSession, extrinsic: ExtrinsicHold) -> None:
        self._node, self._cfg, self._session, self._extrinsic = node, cfg, session, extrinsic
        self.status = NodeStatus(cfg.input_timeout)
        if extrinsic.ignored is not None:  # a lifecycle node's reactivation: the outputs still use the old one
            self.status.stand("extrinsic", extrinsic.ignored)
        self._scan_status = ScanStatus(self.status)
        self._target: Optional[tuple[Incoming, Scan]] = None  # pair mode: the last target, decoded once
        self._outputs = NodeOutputs(node, cfg)
        self.tf_buffer: Any = None  # a tf2_ros.Buffer where tf2_ros exists (a test may set a stand-in)
        self._tf_listener: Any = None
        if tf2_ros is not None:
            self.tf_buffer = tf2_ros.Buffer()
            self._tf_listener = tf2_ros.TransformListener(self.tf_buffer, node)
        self._arrival_period = ArrivalPeriod()  # the input's period as it arrives: what a scan's budget counts in
        self._worker = BoundedWorker(self._process, maxsize=cfg.queue_size, on_error=self._on_worker_error,
                                     name="cemnet_align")
        self._subscriptions: list = []
        self._subscribe(cfg)
        self._services = NodeServices(node, session, cfg, self._warn)
        # On the steady clock: ROS time stands still with use_sim_time until /clock arrives, and so would they.
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._timers = [node.create_timer(1.0, self._publish_diagnostics, clock=steady)]
        if cfg.local_map_period > 0:
            self._timers.append(node.create_timer(cfg.local_map_period, self._publish_local_map))
        if self._outputs.path is not None:
            self._timers.append(node.create_timer(cfg.path_period, self._outputs.path.publish))

    def engine_ready(self, seconds: float, detail: str = "") -> None:
        """The session's engine has loaded (in ``seconds``; ``detail``: how its kernels came): scans queued meanwhile
        are processed now."""
        self.status.ready = True
        drops = self._worker.stats().drops
        self._node.get_logger().info(f"engine ready after {seconds:.1f} s" + (f" ({detail})" if detail else "") +
                                     (f"; {drops} scans dropped meanwhile (queue_size {self._cfg.queue_size})"
                                      if drops else ""))

    def destroy(self) -> None:
        """Stop taking input, finish or drop the queue, and destroy every entity this made on the node."""
        for subscription in self._subscriptions:
            self._node.destroy_subscription(subscription)
        for timer in self._timers:
            self._node.destroy_timer(timer)
        self._worker.close()
        if self._tf_listener is not None:
            self._tf_listener.unregister()
        self._services.destroy()
        self._outputs.destroy()

    def _subscribe(self, cfg: Any) -> None:
        reliability = ReliabilityPolicy.BEST_EFFORT if cfg.qos_reliability == "best_effort" \
            else ReliabilityPolicy.RELIABLE
        input_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=cfg.qos_depth, reliability=reliability,
                               durability=DurabilityPolicy.VOLATILE)
        if cfg.mode == "sequential":
            self._input_topic = cfg.input_topic
            self._subscriptions.append(
                self._node.create_subscription(PointCloud2, cfg.input_topic, self._on_scan, input_qos, raw=True))
            self.status.input_topic = self._subscriptions[0].topic_name  # resolved: namespace, remaps
            return
        target_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=cfg.qos_depth,
                                reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.TRANSIENT_LOCAL) if cfg.target_transient_local \
            else input_qos
        self._pairs: PairMatcher = PairMatcher(int(cfg.pair_tolerance * 1e9), cfg.qos_depth, cfg.qos_depth)
        self._input_topic = cfg.source_topic
        self._subscriptions += [
            self._node.create_subscription(PointCloud2, cfg.source_topic, self._on_source, input_qos, raw=True),
            self._node.create_subscription(PointCloud2, cfg.target_topic, self._on_target, target_qos, raw=True)]
        self.status.input_topic = self._subscriptions[0].topic_name

    # -- inputs (executor thread: CDR bytes + stamp, enqueue; no deserializing) ------------------------------
    def _incoming(self, payload: bytes, topic_kind: str) -> Optional[Incoming]:
        self.status.input_arrived()
        try:
            return Incoming.of(payload, topic_kind)
        except ScanRejected as exc:
            self._report(self._scan_status.rejected(exc.kind, f"{topic_kind} cloud rejected: {exc}", None))
            return None

    def _on_scan(self, payload: bytes) -> None:
        self._arrival_period.arrived(time.monotonic())
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
        for source in unpaired:
            self._report(self._scan_status.unpaired(source.stamp_ns, self._pairs.tolerance_ns))
        for pair in ready:
            self._submit(pair)

    def _submit(self, item: Any) -> None:
        if not self._worker.submit(item):
            loading = "" if self.status.ready else " while the engine loads"
            self._warn("drop", f"queue full{loading}: the oldest scan was dropped "
                               f"({self._worker.stats().drops} so far; queue_size {self._cfg.queue_size})")

    # -- worker thread ---------------------------------------------------------------------------------------
    def _process(self, item: Any) -> None:
        self._session.begin_scan()
        try:
            result, source, frame = self._sequential(item) if isinstance(item, Incoming) else self._pair(*item)
        except ScanRejected as exc:
            self._report(self._scan_status.rejected(exc.kind, str(exc), _stamp_of(item)))
            return
        self.status.scan_frame(source.msg.header.frame_id)  # a registered scan's: not a foreign, refused one
        for stamp_ns in result.step.vouched_late:
            self._report(self._scan_status.vouched_late(stamp_ns))
        self._report(self._scan_status.step(result.step))
        self._outputs.step(result, source, frame)
        self._extrinsic.output_published()

    def _decode(self, item: Incoming) -> Scan:
        scan = decode(item, self._session.config.preprocess.deskew,
                      lambda payload: deserialize_message(payload, PointCloud2))
        self.status.decoded()
        self._log_warnings(self._scan_status.admitted(scan.warnings))
        return scan

    def _sequential(self, item: Incoming) -> tuple[StepResult, Scan, str]:
        scan = self._decode(item)
        frame_id = scan.msg.header.frame_id
        self._sensor_extrinsic(frame_id)
        return (self._session.process(scan, frame_id, self._now_ns(), self._worker.stats().depth,
                                      self._arrival_period.seconds), scan, self._cfg.odom_frame)

    def _pair(self, source_item: Incoming, target_item: Incoming) -> tuple[StepResult, Scan, str]:
        if self._target is None or self._target[0] is not target_item:  # a latched target is decoded once
            self._target = (target_item, self._decode(target_item))
        target, source = self._target[1], self._decode(source_item)
        target_frame = target.msg.header.frame_id
        result = self._session.align_pair(source, target, source.msg.header.frame_id, target_frame, self._now_ns())
        return result, source, target_frame or self._cfg.odom_frame

    def _now_ns(self) -> int:
        return self._node.get_clock().now().nanoseconds

    def _sensor_extrinsic(self, sensor_frame: str) -> None:
        """T_base_sensor from TF until it answers once (where tf2_ros exists), else base_to_sensor; held fixed
        from the first output on (runtime/extrinsic_hold.py)."""
        hold = self._extrinsic
        if self.tf_buffer is None or hold.settled or not sensor_frame or sensor_frame == self._cfg.base_frame:
            return
        frames = f"{self._cfg.base_frame} <- {sensor_frame}"
        try:
            tf = self.tf_buffer.lookup_transform(self._cfg.base_frame, sensor_frame, rclpy.time.Time())
        except Exception as exc:  # noqa: BLE001 - tf2 raises several lookup errors
            self._warn("extrinsic", f"no TF {frames} ({exc}); using base_to_sensor")
            return
        adopted, line = hold.offer(transform_msg_to_matrix(tf.transform), frames)
        if adopted:
            self._session.base = BaseFrame(hold.T_base_sensor)
        if hold.ignored is None:
            self._node.get_logger().info(line)
        else:
            self._node.get_logger().warn(line)
            self.status.stand("extrinsic", line)

    def _on_worker_error(self, item: Any, exc: BaseException) -> None:
        """A scan whose processing raised: counted, logged, and an ERROR verdict (no scan goes unreported)."""
        if self._node.context.ok():  # else shutting down: the publishers are gone, nothing failed
            self._report(self._scan_status.error(exc, _stamp_of(item)))

    # -- reporting (any thread) ------------------------------------------------------------------------------
    def _report(self, outcome: Outcome) -> None:
        if outcome.error is not None:
            self._node.get_logger().error(outcome.error)
        self._log_warnings(outcome.warnings)
        if outcome.verdict is not None:
            self._outputs.scan_status(outcome.verdict, self.status.hardware_id())

    def _warn(self, kind: str, message: str) -> None:
        self._log_warnings(self._scan_status.throttled(kind, message))

    def _log_warnings(self, lines: list[str]) -> None:
        for line in lines:
            self._node.get_logger().warn(line)

    def _publish_local_map(self) -> None:
        if self._outputs.wants_map():
            points = self._session.map_in_odom()
            if points is not None:
                self._outputs.local_map(points)

    def _publish_diagnostics(self) -> None:
        clock_unset = self._node.get_clock().ros_time_is_active and self._now_ns() == 0
        self._outputs.diagnostics(self.status.report(self._worker.stats(), self._session.scale,
                                                      self._node.count_publishers(self._input_topic), clock_unset))
        missing_clock = self.status.missing_clock(clock_unset)
        if missing_clock is not None:
            self._warn("clock", missing_clock)


def _stamp_of(item: Any) -> int:
    """The stamp of a queued item: a scan (sequential mode) or a (source, target) pair (its source's)."""
    return item.stamp_ns if isinstance(item, Incoming) else item[0].stamp_ns
