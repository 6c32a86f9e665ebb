"""Run the scan pipeline (sequential mode) over a bag's clouds and write ``replay.mcap``.

The scans go through the node's own session (:class:`~cemnet_ros.runtime.aligner_session.AlignerSession`):
the result bag holds what align_node (default node name) publishes per scan with the given node parameters,
plus the input's ground truth and /tf_static copied unchanged (same topics, types, header stamps and bag times),
in bag-time order. A cloud message that gives no pose (undecodable, truncated, too few points, rejected by the
aligner, ...) is skipped and counted: the other scans go through the aligner exactly as in a bag without it.

Offline every scan is aligned with the full budgets, the same trajectory on every machine. With ``realtime``
the scans are played into the node's queue at that many times the bag's timing (:mod:`.realtime`): the ones a
live node would drop are dropped, a scan that starts behind gets the node's ``behind_effort``, and every scan the
node's ``scan_budget``.
"""
from __future__ import annotations

import heapq
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np
from tqdm import tqdm

from cemnet_ros.pipeline.errors import ScanRejected
from cemnet_ros.replay.bag_io import (
    ODOMETRY,
    POINTCLOUD2,
    POSE_STAMPED,
    TF_MESSAGE,
    TF_STATIC_TOPIC,
    TF_TOPIC,
    BagError,
    BagReader,
    BagWriter,
    CloudFrame,
    SkippedMessage,
)
from cemnet_ros.replay.realtime import LiveScan, play_live
from cemnet_ros.ros.node_config import NodeConfig
from cemnet_ros.runtime.aligner_session import AlignerSession
from cemnet_ros.runtime.extrinsic import BaseFrame, pose_from_xyz_rpy
from cemnet_ros.runtime.odometry_output import OdometryOutput, aligned_points, tf_parent_child

NODE_NAME = "align_node"  # the node's default name: replay.mcap carries its topics, as a live run would
POSE_TOPIC, ODOM_TOPIC, CLOUD_TOPIC = (f"/{NODE_NAME}/{name}" for name in ("pose", "odometry", "aligned_cloud"))


@dataclass
class ReplayResult:
    """Everything the report and the JSON summary need."""

    stamps_ns: list[int] = field(default_factory=list)
    poses: list[np.ndarray] = field(default_factory=list)
    steps: list[dict] = field(default_factory=list)  # per processed scan: fitness, accepted, reason, ...
    skipped: list[SkippedMessage] = field(default_factory=list)  # cloud messages that gave no pose, in bag order
    rejected: list[dict] = field(default_factory=list)  # those of them the aligner refused (ScanRejected, ...)
    n_messages: int = 0  # cloud messages read (processed + skipped)
    wall_s: float = 0.0
    live: Optional[list[LiveScan]] = None  # with realtime: every cloud message's fate in the node's queue


def output_topics(node: NodeConfig) -> dict[str, str]:
    """Topic -> message type that align_node publishes per scan with these parameters (and replay.mcap holds)."""
    topics = {ODOM_TOPIC: ODOMETRY, POSE_TOPIC: POSE_STAMPED}
    if node.publish_tf:
        topics[TF_TOPIC] = TF_MESSAGE
    if node.publish_aligned_cloud:
        topics[CLOUD_TOPIC] = POINTCLOUD2
    return topics


def copied_topics(reader: BagReader, node: NodeConfig) -> list[str]:
    """The input's topics copied unchanged into replay.mcap: the ground truth and /tf_static (when present)."""
    copies = [t for t in (reader.info.gt_topic, TF_STATIC_TOPIC) if t is not None and t in reader.info.topics]
    clash = sorted(set(copies) & set(output_topics(node)))
    if clash:
        raise BagError(f"input topic(s) {clash} would be overwritten by the replay's outputs")
    return copies


def _step_record(index: int, step, out: OdometryOutput) -> dict:
    """The summary's entry for one processed scan."""
    return {"index": index, "stamp_ns": step.stamp_ns, "fitness": step.fitness, "accepted": step.accepted,
            "reason": step.reason, "latency_s": step.latency_s, "n_points": step.n_points,
            "first": step.relative is None, "recovered": step.recovered, "recovery_reason": step.recovery_reason,
            "degenerate": step.degenerate, "signals": step.signals, "origin": step.origin, "effort": step.effort,
            "polishes": step.polishes, "vouched_late": step.vouched_late, "twist_known": out.twist_known,
            "linear_m_s": out.linear.tolist(), "angular_rad_s": out.angular.tolist()}


class _Replayer:
    """Feeds decoded scans to the aligner and writes align_node's messages for each; counts the skipped ones."""

    def __init__(self, reader: BagReader, aligner, bag: BagWriter, node: NodeConfig) -> None:
        self.bag, self.node, self.topic = bag, node, reader.info.cloud_topic
        self.session = AlignerSession(aligner.config, node, BaseFrame(pose_from_xyz_rpy(node.base_to_sensor)),
                                      make_aligner=lambda _: aligner)
        self.session.load()
        self.result = ReplayResult()
        copies = copied_topics(reader, node)
        self._pending = list(heapq.merge(*([(ns, k, topic, typ, msg) for k, (ns, typ, msg)
                                            in enumerate(reader.messages(topic))] for topic in copies)))
        self._pending.reverse()  # popped from the end, earliest first

    def copy_until(self, stamp_ns: Optional[int]) -> None:
        """Write the copied input messages up to bag time ``stamp_ns`` (all of them with None)."""
        while self._pending and (stamp_ns is None or self._pending[-1][0] <= stamp_ns):
            bag_ns, _, topic, msgtype, msg = self._pending.pop()
            self.bag.write_message(topic, msgtype, msg, bag_ns)

    def skip(self, skipped: SkippedMessage) -> None:
        """Count a message that gives no pose; the first of each kind is also warned about on stderr."""
        if all(s.kind != skipped.kind for s in self.result.skipped):
            tqdm.write(f"cemnet-replay: warning: skipped {skipped.topic} message {skipped.index} "
                       f"(t={skipped.t_s:.3f} s): [{skipped.kind}] {skipped.reason} (further {skipped.kind} "
                       "messages are counted, not shown)", file=sys.stderr)
        self.result.skipped.append(skipped)

    def process(self, frame: CloudFrame, backlog: Optional[int] = None, period_s: Optional[float] = None) -> None:
        """Align one scan as align_node does (``backlog``: newer scans waiting in its queue, ``period_s``: the
        period they arrive at; None: offline) and publish it."""
        try:  # as align_node, without a clock: no future-stamp check offline
            result = self.session.process(frame, frame.frame_id, None, backlog, period_s)
        except ValueError as err:  # ScanRejected (too few points, ...) or a cloud the core refuses
            kind = err.kind if isinstance(err, ScanRejected) else "registration"
            self.skip(SkippedMessage(frame.index, self.topic, frame.stamp_ns, frame.t_s, kind, str(err)))
            self.result.rejected.append({"index": frame.index, "stamp_ns": frame.stamp_ns, "reason": str(err)})
            return
        step, out = result.step, result.out
        self.publish(step.stamp_ns, frame.points, out, result.T_odom_sensor)
        self.result.stamps_ns.append(step.stamp_ns)
        self.result.poses.append(out.T_odom_base)
        self.result.steps.append(_step_record(frame.index, step, out))

    def take(self, item: CloudFrame | SkippedMessage, backlog: Optional[int] = None,
             period_s: Optional[float] = None) -> None:
        """One cloud message of the bag: counted, then skipped or processed."""
        self.result.n_messages += 1
        if isinstance(item, SkippedMessage):
            self.skip(item)
        else:
            self.process(item, backlog, period_s)

    def publish(self, stamp_ns: int, points: np.ndarray, out: OdometryOutput, T_odom_sensor: np.ndarray) -> None:
        """What align_node publishes, offline: pose, odometry, /tf, the aligned cloud (``points`` placed at
        ``T_odom_sensor``), after the copies due by then."""
        node, bag = self.node, self.bag
        self.copy_until(stamp_ns)
        bag.write_pose(POSE_TOPIC, out.T_odom_base, node.odom_frame, stamp_ns)
        bag.write_odometry(ODOM_TOPIC, out.T_odom_base, out.pose_covariance, node.odom_frame, node.base_frame,
                           stamp_ns, linear=out.linear, angular=out.angular, twist_covariance=out.twist_covariance)
        if node.publish_aligned_cloud:
            aligned = aligned_points(points, T_odom_sensor, node.aligned_cloud_voxel)
            bag.write_cloud(CLOUD_TOPIC, aligned, node.odom_frame, stamp_ns)
        if node.publish_tf:
            parent, child, T = tf_parent_child(node.odom_frame, node.base_frame, out.T_odom_base, node.invert_tf)
            bag.write_transform(TF_TOPIC, T, parent, child, stamp_ns)


def run_replay(reader: BagReader, aligner, out_bag: Path, limit: Optional[int], progress: bool,
               node: Optional[NodeConfig] = None, realtime: Optional[float] = None) -> ReplayResult:
    """Feed every scan to the aligner and write the result bag (atomically; see the module docstring). A
    message that gives no pose is skipped with a warning (the first of its kind) and listed in the result.
    ``realtime``: play the scans into the node's queue at that many times the bag's timing."""
    total = reader.info.n_clouds if limit is None else min(limit, reader.info.n_clouds)
    start = time.perf_counter()
    node = node or NodeConfig()
    with BagWriter(out_bag, overwrite=True) as bag, tqdm(total=total, unit="scan", disable=not progress,
                                                          desc="replay") as bar:
        replayer = _Replayer(reader, aligner, bag, node)

        def take(item: CloudFrame | SkippedMessage, backlog: Optional[int] = None,
                 period_s: Optional[float] = None) -> None:
            replayer.take(item, backlog, period_s)
            bar.update()

        if realtime is None:
            for item in reader.scans(limit):
                take(item)
        else:
            replayer.result.live = play_live(reader.scans(limit), lambda item: item.stamp_ns, realtime,
                                             node.queue_size, take)
            bar.update(total - bar.n)  # the dropped ones
        replayer.copy_until(None)
    replayer.result.wall_s = time.perf_counter() - start
    return replayer.result
