#!/usr/bin/env python3
"""Live over DDS: a posed sequence published at RATE x its own timing into align_node as its own process.

The scans (BALM's folder, optionally thinned, or a bag with ground truth) are serialized once and published with
their own spacing (stamps in the past, so that no rate makes them run ahead of the node's clock), from this
process, with the package's Fast DDS profile on both sides (:mod:`benchmarks.dds_probe`). A first scan
repeated warms the node up (engine loading, kernels), then ``~/reset`` starts a fresh map. Prints, per rate:
scans published, odometry received, latency (publish to odometry) p50 / p95 / p99, and the ATE, end drift and
steps off of what came out (scan_status OK = accepted), and every step adjudicated (accepted / flagged, right /
wrong against the data's own optimum too), as scripts/bench_live.py does for the simulated queue.

    python scripts/bench_live_dds.py --balm DIR --thinned 5000 --rates 1 8
    python scripts/bench_live_dds.py --bag bags/kitti_00_6scans.mcap --rates 1 2
    python scripts/bench_live_dds.py --bag QUICK_SHACK_BAG --off 0.12 2 --rates 1 --param queue_size:=32 threads:=1
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path
from typing import Optional

import numpy as np
import rclpy

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # runnable from a fresh checkout without `pip install`
    sys.path.insert(0, str(REPO))

from benchmarks.adjudication import DataOptimum  # noqa: E402
from benchmarks.dds_probe import Probe, cloud_message, dds_environment, node_log, serialized, stamped, start_node  # noqa: E402,E501
from benchmarks.live import bag_sequence, live_table  # noqa: E402
from benchmarks.real import Sequence, StepResult, balm_sequence, sequence_metrics  # noqa: E402
from cemnet_ros.io.atomic import json_text, write_report  # noqa: E402
from cemnet_ros.replay.realtime import latency_percentiles  # noqa: E402

NS = "/live"
WARM_UP_S = 240.0  # the engine loads and, on a first run, the kernels compile


def messages(sequence: Sequence) -> list[bytearray]:
    """Each scan as PointCloud2 CDR bytes (x, y, z, intensity 0), serialized once."""
    clouds = [cloud_message(np.c_[s, np.zeros(len(s))], "lidar") for s in sequence.scans]
    return serialized(clouds)


def warm_up(probe: Probe, first: bytearray, node) -> None:
    """The first scan, repeated, until the node publishes odometry; then a fresh map."""
    deadline, stamp = time.monotonic() + WARM_UP_S, time.time_ns() - 120 * 10 ** 9
    while len(probe.odometry) < 3 and time.monotonic() < deadline and node.poll() is None:
        probe.pub.publish(stamped(first, stamp))
        stamp += 500_000_000
        time.sleep(0.5)
    if len(probe.odometry) < 3 or not probe.reset():
        raise RuntimeError("the node produced no odometry: " + node_log(node)[-2000:])
    time.sleep(1.0)


def play(probe: Probe, sequence: Sequence, msgs: list[bytearray], rate: float) -> dict:
    """Publish every scan at its time / ``rate``; what the node made of them."""
    span_ns = sequence.stamps_ns[-1] - sequence.stamps_ns[0]
    base_ns = time.time_ns() - span_ns - 10 ** 9  # every stamp in the past of the node's clock
    stamps = [base_ns + s - sequence.stamps_ns[0] for s in sequence.stamps_ns]
    published, start = {}, time.monotonic()
    for k, msg in enumerate(msgs):
        due = start + (sequence.stamps_ns[k] - sequence.stamps_ns[0]) * 1e-9 / rate
        time.sleep(max(0.0, due - time.monotonic()))
        published[stamps[k]] = time.monotonic()
        probe.pub.publish(stamped(msg, stamps[k]))
    time.sleep(5.0)  # the queue drains
    arrivals = {stamp: t for t, stamp in probe.odometry}
    accepted = {v.stamp_ns: v.level == 0 for v in probe.verdicts}  # in order: a late OK overrides the flag
    restarted = {v.stamp_ns for v in probe.verdicts if v.map_restarted}
    reasons = {v.stamp_ns: v.message for v in probe.verdicts}
    kept = [k for k, s in enumerate(stamps) if s in probe.poses]
    latencies = [1e3 * (arrivals[stamps[k]] - published[stamps[k]]) for k in kept]
    results = [StepResult(probe.poses[stamps[k]], accepted.get(stamps[k], False), False, np.nan,
                          reasons.get(stamps[k], ""), restarted=stamps[k] in restarted) for k in kept]
    processed = sequence.subset(kept)
    metrics = sequence_metrics(processed, results, DataOptimum(processed.scans)) if kept else {}
    accuracy = {k: metrics.get(k) for k in ("ate_m", "end_drift_pct", "off_accepted", "off_flagged",
                                            "accepted_right", "accepted_wrong", "flagged_right", "flagged_wrong",
                                            "accepted_wrong_steps")}
    return {"rate": rate, "scans": len(msgs), "processed": len(kept), "behind": None,
            **latency_percentiles(latencies), "ms_p50": None, "ms_p95": None, **accuracy}


def main(argv: Optional[list[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--balm", type=Path, help="BALM's datas/benchmark_realworld folder")
    parser.add_argument("--thinned", type=int, metavar="N", help="BALM thinned to N random points per scan")
    parser.add_argument("--bag", type=Path, help="a bag with ground truth instead of BALM")
    parser.add_argument("--rates", type=float, nargs="+", default=[1.0, 4.0])
    parser.add_argument("--off", type=float, nargs=2, metavar=("M", "DEG"),
                        help="a step wrong by more than this (a bag carries no thresholds: give its set's, "
                             "../shared/real_sets/README.md; default: benchmarks.real's)")
    parser.add_argument("--param", nargs="+", default=[], metavar="NAME:=VALUE",
                        help="node parameters under test (docs/node.md), as ros2 run's -p takes them")
    parser.add_argument("--out", type=Path, default=REPO / "results" / "bench_live_dds.json")
    args = parser.parse_args(argv)
    under_test = dict(item.split(":=", 1) for item in args.param if ":=" in item)
    if len(under_test) != len(args.param):
        parser.error("--param takes NAME:=VALUE")
    if (args.balm is None) == (args.bag is None):
        parser.error("give --balm DIR or --bag BAG")
    sequence = bag_sequence(args.bag) if args.bag else balm_sequence(args.balm)
    if args.off:
        sequence = dataclasses.replace(sequence, off=tuple(args.off))
    if args.thinned:
        sequence = sequence.keyframes(1, args.thinned)
    msgs = messages(sequence)
    os.environ.update(dds_environment())  # before rclpy starts and the node process inherits it
    rclpy.init()
    rows = []
    try:
        for rate in args.rates:  # a fresh node per rate: nothing carries over
            node = start_node(NS, {"qos_reliability": "reliable", "preprocess.max_range": sequence.max_range,
                                   **under_test})
            probe = Probe(NS, reliable=True)
            try:
                warm_up(probe, msgs[0], node)
                print(f"[bench_live_dds] {sequence.name} at {rate:g}x ...", file=sys.stderr, flush=True)
                method = " ".join(["cemnet over DDS", *args.param])
                rows.append({"sequence": sequence.name, "method": method, **play(probe, sequence, msgs, rate)})
            finally:
                probe.close()
                node.terminate()
                node.wait(20)
    finally:
        rclpy.shutdown()
    print(live_table(rows))
    write_report(args.out, json_text({"rows": rows}))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
