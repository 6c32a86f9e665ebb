"""Full-size scans over DDS into align_node as a separate process: delivery, capacity and 10x overload.

    python scripts/bench_dds.py --out results/bench_dds.json [--rate-seconds 60] [--overload-seconds 30]

Real 124k-point KITTI scans (../shared/data/kitti_sample, played 0..5..0, stamped with the wall clock) are
published from this process (``--publisher serialized``: CDR bytes made once, as cheap as a C++ driver; ``python``:
rclpy serializes each one here, on the cores the node needs) with the package's Fast DDS profile on both sides,
as the launch file does (benchmarks.dds_probe):

1. ``rate``: best effort at 10 Hz: received / published, processed / published, drops;
2. ``capacity``: closed loop (the next scan when the previous odometry arrived): the rate the node sustains,
   measured in each session (a node subscribing best effort, then one subscribing reliable);
3. ``overload``: 100 Hz in each session: the odometry rate against that session's capacity, and the node's RSS
   (max - min) over the run.
Capacity and overload use one scan repeated (a standing robot): under overload the node aligns every ~4th scan,
and the 6 scans played forth and back would then jump metres between aligned scans (global searches), which
measures the input's motion rather than the node's throughput. The 10 Hz run uses the moving sequence.
Prints a table; the JSON is written atomically.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import rclpy

from benchmarks.dds_probe import (
    REPO,
    Probe,
    dds_environment,
    kitti_clouds,
    node_log,
    rss_mb,
    serialized,
    stamped,
    start_node,
)
from cemnet_ros.io.atomic import json_text, write_report

NS = "/bench"


def stream(probe: Probe, msgs: list, rate: float, seconds: float, first: int, pid: int) -> dict:
    """Publish at ``rate`` for ``seconds``; counts and RSS."""
    n, start = int(rate * seconds), time.monotonic()
    odom0, received0, drops0 = len(probe.odometry), probe.counter("received"), probe.counter("queue_drops")
    rss = []
    for i in range(n):
        probe.pub.publish(stamped(msgs[(first + i) % len(msgs)]))
        if i % max(int(rate / 2), 1) == 0:
            rss.append(rss_mb(pid))
        time.sleep(max(0.0, start + (i + 1) / rate - time.monotonic()))
    end = time.monotonic()
    time.sleep(3.0)  # the queue drains, the diagnostics catch up
    published = len(probe.odometry) - odom0
    # The rate while the input streams, after a second of warm-up (a first step after a pause is a recovery).
    steady = [t for t, _ in probe.odometry[odom0:] if start + 1.0 <= t <= end]
    return {"published": n, "seconds": seconds, "received": probe.counter("received") - received0,
            "processed": published, "drops": probe.counter("queue_drops") - drops0,
            "odometry_hz": len(steady) / (end - start - 1.0), "rss_min_mb": min(rss), "rss_max_mb": max(rss)}


def closed_loop(probe: Probe, msgs: list, seconds: float, first: int) -> dict:
    """The next scan once the previous odometry arrived: the node's own capacity."""
    count, start, i = len(probe.odometry), time.monotonic(), 0
    while time.monotonic() - start < seconds:
        before = len(probe.odometry)
        probe.pub.publish(stamped(msgs[(first + i) % len(msgs)]))
        deadline = time.monotonic() + 10.0
        while len(probe.odometry) == before and time.monotonic() < deadline:
            time.sleep(0.001)
        i += 1
    elapsed = time.monotonic() - start
    return {"scans": len(probe.odometry) - count, "seconds": elapsed, "hz": (len(probe.odometry) - count) / elapsed}


def session(reliable: bool, phases: list, msgs: list) -> dict:
    """One node process (subscribing best effort or reliable) through ``phases`` [(name, fn(probe, first, pid))]."""
    node = start_node(NS, {"qos_reliability": "reliable" if reliable else "best_effort"})
    probe = Probe(NS, reliable)
    out, first = {}, 0
    try:
        deadline = time.monotonic() + 180.0  # the engine loads and the kernels compile
        while len(probe.odometry) < 3 and time.monotonic() < deadline and node.poll() is None:
            stream(probe, msgs, 2.0, 1.0, first, node.pid)
            first += 2
        if len(probe.odometry) < 3:
            raise RuntimeError("the node produced no odometry: " + node_log(node)[-2000:])
        time.sleep(2.0)  # the scans queued while the engine loaded are processed before the phases count
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
    parser.add_argument("--publisher", choices=("serialized", "python"), default="serialized",
                        help="serialized: CDR bytes made once (a C++ driver's cost); python: rclpy serializes each "
                             "message in this process, on the cores the node needs")
    args = parser.parse_args()
    clouds = kitti_clouds()
    msgs = serialized(clouds) if args.publisher == "serialized" else clouds
    os.environ.update(dds_environment())  # before rclpy starts and the node process inherits it
    rclpy.init()
    try:
        standing = msgs[:1]
        best_effort = session(False, [
            ("rate_10hz", lambda p, f, pid: stream(p, msgs, 10.0, args.rate_seconds, f, pid)),
            ("capacity_moving", lambda p, f, pid: closed_loop(p, msgs, 20.0, f)),
            ("capacity", lambda p, f, pid: closed_loop(p, standing, 20.0, f)),
            ("overload_100hz", lambda p, f, pid: stream(p, standing, 100.0, args.overload_seconds, f, pid))], msgs)
        reliable = session(True, [
            ("capacity", lambda p, f, pid: closed_loop(p, standing, 20.0, f)),
            ("overload_100hz", lambda p, f, pid: stream(p, standing, 100.0, args.overload_seconds, f, pid))], msgs)
    finally:
        rclpy.try_shutdown()
    results = {"publisher": args.publisher, "points_per_scan": int(clouds[0].width),
               "bytes_per_scan": len(clouds[0].data), "best_effort": best_effort, "reliable": reliable}
    print(table(best_effort, reliable))
    write_report(args.out, json_text(results, indent=2))


def table(best_effort: dict, reliable: dict) -> str:
    """The runs' counts and rates against each session's capacity, then the capacities and the 10 Hz delivery."""
    rate = best_effort["rate_10hz"]
    lines = ["| run | published | received | processed | drops | odometry Hz | capacity Hz | vs capacity | "
             "RSS max-min MB |", "|---|---|---|---|---|---|---|---|---|"]
    for label, r, capacity in (("10 Hz best effort", rate, None),
                               ("100 Hz best effort", best_effort["overload_100hz"], best_effort["capacity"]["hz"]),
                               ("100 Hz reliable", reliable["overload_100hz"], reliable["capacity"]["hz"])):
        versus = "- | -" if capacity is None else f"{capacity:.2f} | {r['odometry_hz'] / capacity:.2f}"
        lines.append(f"| {label} | {r['published']} | {r['received']} | {r['processed']} | {r['drops']} | "
                     f"{r['odometry_hz']:.2f} | {versus} | {r['rss_max_mb'] - r['rss_min_mb']:.0f} |")
    capacity, moving = best_effort["capacity"]["hz"], best_effort["capacity_moving"]["hz"]
    lines.append(f"capacity (closed loop; the session's own, standing): best effort {capacity:.2f} Hz "
                 f"(moving {moving:.2f} Hz), reliable {reliable['capacity']['hz']:.2f} Hz; "
                 f"10 Hz delivery {rate['received'] / rate['published']:.1%}, "
                 f"processed {rate['processed'] / rate['published']:.1%}")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
