"""Full-size scans over DDS into align_node as a separate process: delivery, capacity and 10x overload.

    python scripts/bench_dds.py --out results/bench_dds.json [--rate-seconds 60] [--overload-seconds 30]

Real 124k-point KITTI scans (../shared/data/kitti_sample, played 0..5..0 with stamps at the nominal rate) are
published from this process with the package's Fast DDS profile applied to both sides, as the launch file does:

1. ``rate``: best effort at 10 Hz: received / published, processed / published, drops;
2. ``capacity``: closed loop (the next scan when the previous odometry arrived): the rate the node sustains;
3. ``overload``: 100 Hz, best effort and (a node subscribing reliable) reliable: the odometry rate against the
   capacity, and the node's RSS (max - min) over the run.
Capacity and overload use one scan repeated (a standing robot): under overload the node aligns every ~8th scan,
and the 6 scans played forth and back would then jump metres between aligned scans (global searches), which
measures the input's motion rather than the node's throughput. The 10 Hz run uses the moving sequence.
Prints a table; the JSON is written atomically.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
PROFILE = REPO / "config" / "fastdds_large_data.xml"
KITTI = REPO.parent / "shared" / "data" / "kitti_sample" / "velodyne"
os.environ.setdefault("FASTRTPS_DEFAULT_PROFILES_FILE", str(PROFILE))
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 200)))

import rclpy  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from nav_msgs.msg import Odometry  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import PointCloud2, PointField  # noqa: E402

from cemnet_ros.io.atomic import atomic_write_text, jsonable  # noqa: E402

NS = "/bench"


def kitti_messages() -> list[PointCloud2]:
    """The six scans as PointCloud2 (x, y, z, intensity float32: 16 bytes a point), played forth and back."""
    files = sorted(KITTI.glob("*.bin"))
    if not files:
        sys.exit(f"error: no KITTI scans in {KITTI} (../shared/data is needed for this benchmark)")
    fields = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
              for i, n in enumerate(("x", "y", "z", "intensity"))]
    msgs = []
    for path in files + files[-2:0:-1]:
        scan = np.fromfile(path, dtype=np.float32).reshape(-1, 4)
        msg = PointCloud2(height=1, width=len(scan), fields=fields, is_bigendian=False, point_step=16,
                          row_step=16 * len(scan), is_dense=True, data=scan.tobytes())
        msg.header.frame_id = "velodyne"
        msgs.append(msg)
    return msgs


class Probe:
    """Publisher of the scans and counter of the node's outputs, spinning in a thread."""

    def __init__(self, reliable: bool) -> None:
        self.node = rclpy.create_node("bench_probe")
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE if reliable else
                         ReliabilityPolicy.BEST_EFFORT)
        self.pub = self.node.create_publisher(PointCloud2, f"{NS}/points", qos)
        self.odometry: list[float] = []
        self.verdicts: list[int] = []
        self.diagnostics: dict = {}
        self.node.create_subscription(Odometry, f"{NS}/align_node/odometry",
                                      lambda m: self.odometry.append(time.monotonic()), 100)
        self.node.create_subscription(DiagnosticStatus, f"{NS}/align_node/scan_status",
                                      lambda m: self.verdicts.append(m.level[0]), 500)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 10)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.startswith(f"{NS}/align_node"):
                self.diagnostics = {kv.key: kv.value for kv in status.values}

    def counter(self, key: str) -> int:
        value = self.diagnostics.get(key, "0")
        return int(value) if value.lstrip("-").isdigit() else 0

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()


def start_node(reliable: bool) -> subprocess.Popen:
    args = [sys.executable, "-m", "cemnet_ros.ros.align_node", "--ros-args", "-r", f"__ns:={NS}",
            "-p", f"qos_reliability:={'reliable' if reliable else 'best_effort'}", "--log-level", "warn"]
    return subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def stamped(msgs: list, index: int) -> PointCloud2:
    """Scan ``index`` of the played sequence, stamped at the KITTI rate (10 Hz) whatever the publishing rate."""
    msg = msgs[index % len(msgs)]
    ns = 10 ** 9 + index * 100_000_000
    msg.header.stamp.sec, msg.header.stamp.nanosec = ns // 10 ** 9, ns % 10 ** 9
    return msg


def stream(probe: Probe, msgs: list, rate: float, seconds: float, first: int, pid: int) -> dict:
    """Publish at ``rate`` for ``seconds`` (stamps at the KITTI rate of 10 Hz); counts and RSS."""
    n, start = int(rate * seconds), time.monotonic()
    odom0, received0, drops0 = len(probe.odometry), probe.counter("received"), probe.counter("queue_drops")
    rss = []
    for i in range(n):
        probe.pub.publish(stamped(msgs, first + i))
        if i % max(int(rate / 2), 1) == 0:
            rss.append(rss_mb(pid))
        time.sleep(max(0.0, start + (i + 1) / rate - time.monotonic()))
    time.sleep(3.0)  # the queue drains, the diagnostics catch up
    published = len(probe.odometry) - odom0
    return {"published": n, "seconds": seconds, "received": probe.counter("received") - received0,
            "processed": published, "drops": probe.counter("queue_drops") - drops0,
            "odometry_hz": published / (seconds + 3.0), "rss_min_mb": min(rss), "rss_max_mb": max(rss)}


def closed_loop(probe: Probe, msgs: list, seconds: float, first: int) -> dict:
    """The next scan once the previous odometry arrived: the node's own capacity."""
    count, start, i = len(probe.odometry), time.monotonic(), 0
    while time.monotonic() - start < seconds:
        before = len(probe.odometry)
        probe.pub.publish(stamped(msgs, first + i))
        deadline = time.monotonic() + 10.0
        while len(probe.odometry) == before and time.monotonic() < deadline:
            time.sleep(0.001)
        i += 1
    elapsed = time.monotonic() - start
    return {"scans": len(probe.odometry) - count, "seconds": elapsed, "hz": (len(probe.odometry) - count) / elapsed}


def session(reliable: bool, phases: list, msgs: list) -> dict:
    """One node process (subscribing best effort or reliable) through ``phases`` [(name, fn(probe, first, pid))]."""
    node = start_node(reliable)
    probe = Probe(reliable)
    out, first = {}, 0
    try:
        deadline = time.monotonic() + 180.0  # the engine loads and the kernels compile
        while len(probe.odometry) < 3 and time.monotonic() < deadline and node.poll() is None:
            stream(probe, msgs, 2.0, 1.0, first, node.pid)
            first += 2
        if len(probe.odometry) < 3:
            raise RuntimeError("the node produced no odometry: " + (node.stderr.read() if node.poll() else ""))
        first += 100
        for name, phase in phases:
            print(f"[bench_dds] {name} ...", file=sys.stderr, flush=True)
            out[name] = phase(probe, first, node.pid)
            first += 10_000
    finally:
        probe.close()
        node.terminate()
        node.wait(20)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=REPO / "results" / "bench_dds.json")
    parser.add_argument("--rate-seconds", type=float, default=60.0)
    parser.add_argument("--overload-seconds", type=float, default=30.0)
    args = parser.parse_args()
    msgs = kitti_messages()
    rclpy.init()
    try:
        standing = msgs[:1]
        best_effort = session(False, [
            ("rate_10hz", lambda p, f, pid: stream(p, msgs, 10.0, args.rate_seconds, f, pid)),
            ("capacity_moving", lambda p, f, pid: closed_loop(p, msgs, 20.0, f)),
            ("capacity", lambda p, f, pid: closed_loop(p, standing, 20.0, f)),
            ("overload_100hz", lambda p, f, pid: stream(p, standing, 100.0, args.overload_seconds, f, pid))], msgs)
        reliable = session(True, [
            ("overload_100hz", lambda p, f, pid: stream(p, standing, 100.0, args.overload_seconds, f, pid))], msgs)
    finally:
        rclpy.try_shutdown()
    capacity = best_effort["capacity"]["hz"]
    rate = best_effort["rate_10hz"]
    results = {"points_per_scan": int(msgs[0].width), "bytes_per_scan": len(msgs[0].data),
               "best_effort": best_effort, "reliable": reliable, "capacity_hz": capacity}
    print("| run | published | received | processed | drops | odometry Hz | vs capacity | RSS max-min MB |")
    print("|---|---|---|---|---|---|---|---|")
    for label, r in (("10 Hz best effort", rate), ("100 Hz best effort", best_effort["overload_100hz"]),
                     ("100 Hz reliable", reliable["overload_100hz"])):
        print(f"| {label} | {r['published']} | {r['received']} | {r['processed']} | {r['drops']} | "
              f"{r['odometry_hz']:.2f} | {r['odometry_hz'] / capacity:.2f} | {r['rss_max_mb'] - r['rss_min_mb']:.0f} |")
    print(f"capacity (closed loop, standing): {capacity:.2f} Hz, moving {best_effort['capacity_moving']['hz']:.2f} Hz; "
          f"10 Hz delivery {rate['received'] / rate['published']:.1%}, "
          f"processed {rate['processed'] / rate['published']:.1%}")
    atomic_write_text(args.out, json.dumps(jsonable(results), indent=2))


if __name__ == "__main__":
    main()
