#!/usr/bin/env python3
"""Sustained-rate benchmark: KITTI-size scans (~124k points) fed at 10 Hz through the node's pipeline.

A producer thread submits scans into the pipeline's bounded worker queue (``BoundedWorker``, as align_node
does) on a fixed clock; the worker runs ``ScanAligner.process`` with default parameters. Reports the sustained
processing rate, latency (submit -> result) p50/p95, drops, and whether it kept up. The same stream then goes
through a plain point-to-point ICP pipeline (same queue, same voxel grid) as a baseline measured in this run.

Scans: the 6 real KITTI Velodyne scans from ../shared when present (played forwards and backwards so that
consecutive scans stay neighbours), else ray-cast synthetic 64-beam scans of the same size.

    python scripts/bench_throughput.py --duration 30
    python -m scripts.bench_throughput --duration 60 --rate 10 --no-baseline
"""
from __future__ import annotations

import argparse
import itertools
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # runnable from a fresh checkout without `pip install`
    sys.path.insert(0, str(REPO))

from benchmarks.shared import SHARED  # noqa: E402
from benchmarks.speed import ping_pong_cycle  # noqa: E402
from cemnet_ros.data.kitti import kitti_scans  # noqa: E402
from cemnet_ros.ros.node_config import NodeConfig  # noqa: E402
from cemnet_ros.runtime.worker import BoundedWorker  # noqa: E402

KITTI = SHARED / "data" / "kitti_sample"


def kitti_points() -> list[np.ndarray]:
    """The sample's full-resolution scans, float64 (their poses are not needed here)."""
    return [points.astype(np.float64) for points, _ in kitti_scans(KITTI)]


def synthetic_scans(n: int = 6) -> list[np.ndarray]:
    """HDL-64-like scans (~124k points) of the synthetic courtyard along its smooth path."""
    from cemnet_ros.data.scenes import LidarModel, courtyard_scene, lidar_scan, synthetic_trajectory

    lidar = LidarModel(n_beams=64, n_azimuth=1940, elevation_deg=(-24.8, 2.0))
    scene, rng = courtyard_scene(), np.random.default_rng(0)
    return [lidar_scan(scene, pose, lidar, rng).astype(np.float64) for pose in synthetic_trajectory(n)]


@dataclass
class BenchResult:
    """Counts over the whole run; rate and latency over the steady state (the stream, not the final drain)."""

    name: str
    submitted: int
    processed: int
    errors: int
    drops: int
    stream_s: float
    done_in_stream: int  # results finished while the producer was still running
    latencies_s: list[float] = field(default_factory=list)  # submit -> result, items started during the stream
    startup_drops: int = 0  # dropped before the first tracked step (the odometry's start-up global searches)

    @property
    def rate_hz(self) -> float:
        return self.done_in_stream / self.stream_s

    def summary(self, target_hz: float) -> str:
        lat = np.asarray(self.latencies_s) * 1e3
        p50, p95 = (np.percentile(lat, 50), np.percentile(lat, 95)) if lat.size else (np.nan, np.nan)
        steady_drops = self.drops - self.startup_drops
        kept_up = steady_drops == 0 and self.rate_hz >= 0.95 * target_hz
        return (f"{self.name:>8}: {self.rate_hz:.2f} scans/s sustained over {self.stream_s:.0f} s "
                f"({self.processed}/{self.submitted} processed incl. drain); latency p50 {p50:.0f} ms, "
                f"p95 {p95:.0f} ms; drops {self.drops} ({self.startup_drops} before the first tracked step); "
                f"errors {self.errors}; kept up with {target_hz:g} Hz after it: "
                f"{'YES' if kept_up else 'NO'}")


class Producer(threading.Thread):
    """Submits (submit time, scan, stamp_ns) into ``worker`` at ``rate_hz`` for ``duration_s``, the scans in
    ping-pong order (consecutive scans are neighbours); ``submitted`` counts them."""

    def __init__(self, worker: BoundedWorker, scans: list[np.ndarray], rate_hz: float, duration_s: float) -> None:
        super().__init__(name="bench-producer", daemon=True)
        self.worker, self.scans, self.rate_hz, self.duration_s = worker, scans, rate_hz, duration_s
        self.submitted = 0
        self.stop = threading.Event()

    def run(self) -> None:
        period, start, order = 1.0 / self.rate_hz, time.monotonic(), itertools.cycle(ping_pong_cycle(len(self.scans)))
        while not self.stop.is_set():
            due = start + self.submitted * period
            if due - start >= self.duration_s:
                return
            time.sleep(max(0.0, due - time.monotonic()))
            stamp_ns = int(1e18) + int(self.submitted * period * 1e9)
            self.worker.submit((time.monotonic(), self.scans[next(order)], stamp_ns))
            self.submitted += 1


def run_stream(name: str, process: Callable[[np.ndarray, int], None], scans: list[np.ndarray], rate_hz: float,
               duration_s: float, queue_size: int) -> BenchResult:
    """Submit scans at ``rate_hz`` for ``duration_s`` into a BoundedWorker running ``process``; then drain."""
    records: list[tuple[float, float, float]] = []  # (submitted, started, done), monotonic seconds
    startup_drops = []

    def handle(item):
        submitted, points, stamp_ns = item
        started = time.monotonic()
        step = process(points, stamp_ns)
        records.append((submitted, started, time.monotonic()))
        tracked = len(records) > 1 and not getattr(step, "recovered", False)  # the ICP baseline has no recovery
        if tracked and not startup_drops:
            startup_drops.append(worker.stats().drops)

    worker = BoundedWorker(handle, maxsize=queue_size, name=f"bench-{name}")
    producer = Producer(worker, scans, rate_hz, duration_s)
    start = time.monotonic()
    producer.start()
    try:
        producer.join()
        end = time.monotonic()
        worker.wait_idle(timeout=120.0)  # drain: queued scans then wait for their predecessors, not realistic
    finally:
        producer.stop.set()
        worker.close()
    stats = worker.stats()
    return BenchResult(name, producer.submitted, stats.processed, stats.errors, stats.drops, end - start,
                       sum(1 for _, _, done in records if done <= end),
                       [done - sub for sub, started, done in records if started <= end],
                       startup_drops[0] if startup_drops else 0)


def cemnet_process():
    from cemnet_ros.pipeline.aligner import ScanAligner

    aligner = ScanAligner()
    return aligner.process, aligner


def icp_process(voxel: float, scale: float):
    """Plain sequential point-to-point ICP odometry on the pipeline's voxel grid (scipy k-d tree, identity init)."""
    from cemnet_ros.eval.baselines import ICPConfig, icp
    from cemnet_ros.pipeline.steps.preprocess import voxel_downsample

    state = {"prev": None}
    config = ICPConfig(max_iterations=30, max_distance=3.0 * (voxel if voxel > 0 else scale / 100.0))

    def process(points: np.ndarray, stamp_ns: int) -> None:
        cloud = voxel_downsample(points, voxel)
        if state["prev"] is not None:
            icp(cloud, state["prev"], config)
        state["prev"] = cloud

    return process


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=30.0, help="seconds of streaming per pipeline")
    parser.add_argument("--rate", type=float, default=10.0, help="scan rate in Hz (KITTI: 10)")
    parser.add_argument("--queue-size", type=int, default=NodeConfig().queue_size,
                        help="worker queue bound (default: align_node's)")
    parser.add_argument("--source", choices=("auto", "kitti", "synthetic"), default="auto")
    parser.add_argument("--no-baseline", action="store_true", help="skip the plain-ICP baseline stream")
    args = parser.parse_args(argv)
    if args.duration <= 0 or args.rate <= 0:
        parser.error("--duration and --rate must be > 0")
    use_kitti = args.source == "kitti" or (args.source == "auto" and KITTI.is_dir())
    if args.source == "kitti" and not KITTI.is_dir():
        parser.error(f"{KITTI} not found")
    scans = kitti_points() if use_kitti else synthetic_scans()
    print(f"scans: {'KITTI (real)' if use_kitti else 'synthetic'}, {len(scans)} distinct, "
          f"{int(np.mean([len(s) for s in scans]))} points each; {args.rate:g} Hz for {args.duration:g} s, "
          f"queue {args.queue_size}")
    process, aligner = cemnet_process()
    process(scans[0], 0)  # warm-up: loads weights, compiles the numba kernels
    process(scans[1], 100_000_000)
    voxel, scale = aligner.voxel, aligner.scale
    aligner.reset()
    results = [run_stream("CEMNet", process, scans, args.rate, args.duration, args.queue_size)]
    print(results[0].summary(args.rate), flush=True)
    if not args.no_baseline:
        results.append(run_stream("ICP", icp_process(voxel, scale), scans, args.rate, args.duration, args.queue_size))
        print(results[1].summary(args.rate))
        if results[1].rate_hz > 0:
            print(f"CEMNet / ICP sustained rate: {results[0].rate_hz / results[1].rate_hz:.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
