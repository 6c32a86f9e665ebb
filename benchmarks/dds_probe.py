"""A harness for node benchmarks over DDS: the node under test as a process, a scan publisher, an output recorder.

Used by ``scripts/bench_dds.py`` (delivery, capacity, overload) and ``scripts/soak_node.py`` (hours-long
behaviour under faults). Scans are published either as PointCloud2 objects (rclpy serializes each one, ~3 ms
in Python for 2 MB) or as CDR bytes serialized once with the stamp patched in place, as cheap as a C++
driver's publish: on a 2-core machine the harness would otherwise take the cores the node needs.
"""
from __future__ import annotations

import os
import random
import struct
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from nav_msgs.msg import Odometry
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from sensor_msgs.msg import PointCloud2, PointField
from std_srvs.srv import Trigger

from benchmarks.shared import REPO, SHARED
from cemnet_ros.ros.scans import HEADER_STAMP_OFFSET
from cemnet_ros.runtime.extrinsic import pose_msg_to_matrix

PROFILE = REPO / "config" / "fastdds_large_data.xml"
KITTI = SHARED / "data" / "kitti_sample" / "velodyne"


def dds_environment() -> dict[str, str]:
    """The environment of a benchmark's processes: this host only, a domain of its own and the shipped profile
    (a domain or profile already set wins). Apply it before ``rclpy.init`` and before starting the node."""
    return {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
            "ROS_DOMAIN_ID": os.environ.get("ROS_DOMAIN_ID") or str(random.randint(1, 200)),
            "FASTRTPS_DEFAULT_PROFILES_FILE": os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE") or str(PROFILE)}


def kitti_clouds(directory: Path = KITTI, frame_id: str = "velodyne") -> list[PointCloud2]:
    """The KITTI scans (x, y, z, intensity float32: 16 bytes a point) played forth and back: 0..5..1."""
    files = sorted(directory.glob("*.bin"))
    if not files:
        sys.exit(f"error: no KITTI scans in {directory} (../shared/data is needed for this benchmark)")
    return [cloud_message(np.fromfile(path, dtype=np.float32).reshape(-1, 4), frame_id)
            for path in files + files[-2:0:-1]]


def cloud_message(xyzi: np.ndarray, frame_id: str = "velodyne") -> PointCloud2:
    fields = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
              for i, n in enumerate(("x", "y", "z", "intensity"))]
    data = np.ascontiguousarray(xyzi, dtype=np.float32)
    msg = PointCloud2(height=1, width=len(data), fields=fields, is_bigendian=False, point_step=16,
                      row_step=16 * len(data), is_dense=True, data=data.tobytes())
    msg.header.frame_id = frame_id
    return msg


def serialized(msgs: list) -> list[bytearray]:
    """Each message's CDR bytes, to be stamped by :func:`stamped` (no serialization per publish)."""
    return [bytearray(serialize_message(m)) for m in msgs]


def stamped(msg: Any, stamp_ns: Optional[int] = None) -> Any:
    """``msg`` (a PointCloud2 or its CDR bytes) stamped ``stamp_ns`` (default: the wall clock, as a driver)."""
    sec, nanosec = divmod(time.time_ns() if stamp_ns is None else stamp_ns, 10 ** 9)
    if isinstance(msg, bytearray):
        struct.pack_into("<iI", msg, HEADER_STAMP_OFFSET, sec, nanosec)
        return bytes(msg)
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
    return msg


def start_node(namespace: str, params: dict, log_level: str = "warn", env: Optional[dict] = None
               ) -> subprocess.Popen:
    """``align_node`` as a process in ``namespace`` with ``params`` (and ``env``); its log goes to a temporary
    file (:func:`node_log`), never to a pipe that a long run would fill and block the node on."""
    args = [sys.executable, "-m", "cemnet_ros.ros.align_node", "--ros-args", "-r", f"__ns:={namespace}",
            "--log-level", log_level]
    for name, value in params.items():
        args += ["-p", f"{name}:={value}"]
    log = tempfile.TemporaryFile(mode="w+")
    process = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=log, text=True, env=env)
    process.log = log  # type: ignore[attr-defined]
    return process


def node_log(process: subprocess.Popen) -> str:
    """What a node started by :func:`start_node` has logged so far."""
    log = process.log  # type: ignore[attr-defined]
    log.flush()
    log.seek(0)
    return log.read()


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


@dataclass
class Verdict:
    """One ``~/scan_status``: the node's verdict on one input message."""

    arrival: float  # time.monotonic() at the probe
    stamp_ns: Optional[int]  # None when the node could not read the message's stamp
    level: int  # 0 OK, 1 flagged, 2 rejected
    rejected: str  # the kind, "" unless rejected
    map_restarted: bool = False  # the node's map began again from this scan
    message: str = ""  # why it was flagged ("ok" when not)


class Probe:
    """Publisher of the scans and recorder of the node's outputs, spinning in a thread."""

    def __init__(self, namespace: str, reliable: bool, name: str = "bench_probe") -> None:
        self.node = node = rclpy.create_node(name)
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE if reliable else
                         ReliabilityPolicy.BEST_EFFORT)
        self.pub = node.create_publisher(PointCloud2, f"{namespace}/points", qos)
        self.odometry: list[tuple[float, int]] = []  # (arrival, stamp_ns)
        self.poses: dict[int, np.ndarray] = {}  # stamp_ns -> the odometry's pose T_odom_base
        self.verdicts: list[Verdict] = []
        self.diagnostics: dict = {}
        self._name = f"{namespace}/align_node"
        node.create_subscription(Odometry, f"{self._name}/odometry", self._on_odometry, 100)
        node.create_subscription(DiagnosticStatus, f"{self._name}/scan_status", self._on_verdict, 500)
        node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 10)
        self._reset = node.create_client(Trigger, f"{self._name}/reset")
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def _on_odometry(self, msg: Odometry) -> None:
        stamp = msg.header.stamp
        stamp_ns = stamp.sec * 10 ** 9 + stamp.nanosec
        self.odometry.append((time.monotonic(), stamp_ns))
        self.poses[stamp_ns] = pose_msg_to_matrix(msg.pose.pose)

    def _on_verdict(self, msg: DiagnosticStatus) -> None:
        values = {kv.key: kv.value for kv in msg.values}
        self.verdicts.append(Verdict(time.monotonic(), int(msg.name) if msg.name.lstrip("-").isdigit() else None,
                                     msg.level[0], values.get("rejected", ""),
                                     values.get("map_restarted", "") == "True", msg.message))

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.startswith(self._name):
                self.diagnostics = {kv.key: kv.value for kv in status.values}

    def counter(self, key: str) -> int:
        value = self.diagnostics.get(key, "0")
        return int(value) if value.lstrip("-").isdigit() else 0

    def reset(self, timeout: float = 5.0) -> bool:
        """Call ``~/reset``; True when the node answered."""
        if not self._reset.wait_for_service(timeout_sec=timeout):
            return False
        future = self._reset.call_async(Trigger.Request())
        deadline = time.monotonic() + timeout
        while not future.done() and time.monotonic() < deadline:
            time.sleep(0.01)
        return future.done() and future.result().success

    def close(self) -> None:
        """Stop spinning and wait for the thread: a process that exits while it spins aborts in C++."""
        self.executor.shutdown()
        self.thread.join(10.0)
        self.node.destroy_node()
