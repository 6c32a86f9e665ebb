"""Soak: align_node as a process fed real scans at 10 Hz for minutes, with faults injected every few seconds.

    python scripts/soak_node.py --minutes 10 --out results/soak [--fault-every 3]

Real 124k-point KITTI scans (../shared/data/kitti_sample, played forth and back, wall-clock stamps, the
package's DDS profile on both sides). Every ``--fault-every`` seconds one fault, in turn:

- ``bad_cloud``: a message of the hostile corpus (benchmarks.hostile; malformed, degenerate, a sector,
  another robot's frame, bytes that do not deserialize, ...), in place of that period's scan;
- ``stamp_ahead``: a scan stamped 60 s ahead (refused: beyond the clock tolerance), then the stream goes on;
- ``stamp_back``: a scan stamped 2 s back (out of order);
- ``burst``: 30 scans at 100 Hz (the queue drops the oldest: counted, not silent);
- ``pause``: 2 s without scans (the next step runs the global search);
- ``reset``: ``~/reset`` (the map restarts; the pose stays continuous).

Prints and writes (atomically) ``summary.json`` and ``soak.png``: the RSS slope after warm-up (MB/min), the
end-to-end latency (publish -> verdict) percentiles per minute, and the accounting of every message published:
a verdict on ``~/scan_status`` (accepted, flagged or rejected with its kind) or a counted queue drop; whatever
is neither is reported as lost.
"""
from __future__ import annotations

import argparse
import os
import random
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from builtin_interfaces.msg import Time
from sensor_msgs.msg import PointCloud2, PointField

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
from benchmarks.hostile import FRAME, corpus
from cemnet_ros.io.atomic import atomic_write_bytes, json_text, write_report

NS = "/soak"
RATE_HZ = 10.0
WARM_UP_S = 60.0  # excluded from the RSS slope: the allocator and the map grow to their working size
FAULTS = ("bad_cloud", "stamp_ahead", "bad_cloud", "burst", "stamp_back", "bad_cloud", "pause", "reset")


class Soak:
    """The stream, the faults and the record of what was published when."""

    def __init__(self, probe: Probe, scans: list, clouds: list, pid: int) -> None:
        self.probe, self.scans, self.clouds, self.pid = probe, scans, clouds, pid
        self.index = 0  # the next scan of the played sequence
        self.published: dict[int, float] = {}  # stamp_ns -> time.monotonic() at publishing (each one unique)
        self.unstamped = 0  # published messages whose stamp the node cannot read (no verdict by stamp)
        self.bad: dict[int, str] = {}  # stamp_ns -> hostile case name, for the bad clouds published under a stamp
        self.faults: list[tuple[float, str, str]] = []  # (time, fault, detail)
        self.rss: list[tuple[float, float]] = []
        self._rng = random.Random(0)
        self._last_stamp_ns = 0

    def _stamp(self, offset_ns: int = 0) -> int:
        """A wall-clock stamp, strictly after the last one (so that every message is told apart)."""
        ns = max(time.time_ns(), self._last_stamp_ns + 1)
        self._last_stamp_ns = ns
        return ns + offset_ns

    def publish_scan(self, offset_ns: int = 0) -> None:
        stamp_ns = self._stamp(offset_ns)
        self.probe.pub.publish(stamped(self.scans[self.index % len(self.scans)], stamp_ns))
        self.published[stamp_ns] = time.monotonic()
        self.index += 1

    def publish_bad_cloud(self) -> str:
        stamp_ns = self._stamp()
        # The 2 M-point case is left out (~1 s each); stamp faults are relative to the last stamp published.
        cases = [c for c in corpus(self._last_published_stamp()) if c.category != "size"]
        case = cases[self._rng.randrange(len(cases))]
        points = np.frombuffer(bytes(self.clouds[self.index % len(self.clouds)].data), np.float32).reshape(-1, 4)
        msg = case.build(PointCloud2, PointField, points[:, :3].astype(np.float64),
                         Time(sec=stamp_ns // 10 ** 9, nanosec=stamp_ns % 10 ** 9))
        self.probe.pub.publish(msg)
        if isinstance(msg, bytes) or case.category == "stamp":
            self.unstamped += 1  # its stamp is not this one (or not readable): counted by the node's totals
        else:
            self.published[stamp_ns] = time.monotonic()
            self.bad[stamp_ns] = case.name
        return case.name

    def _last_published_stamp(self) -> int:
        return max(self.published) if self.published else self._last_stamp_ns

    def inject(self, fault: str, now: float) -> None:
        detail = ""
        if fault == "bad_cloud":
            detail = self.publish_bad_cloud()
        elif fault == "stamp_ahead":
            self.publish_scan(offset_ns=60 * 10 ** 9)
        elif fault == "stamp_back":
            self.publish_scan(offset_ns=-2 * 10 ** 9)
        elif fault == "burst":
            for _ in range(30):
                self.publish_scan()
                time.sleep(0.01)
        elif fault == "pause":
            time.sleep(2.0)
        elif fault == "reset":
            detail = "answered" if self.probe.reset() else "no answer"
        self.faults.append((now, fault, detail))


def run(args: argparse.Namespace) -> dict:
    """The node started, warmed up, then soaked for ``args.minutes``: the summary of what happened."""
    clouds = kitti_clouds(frame_id=FRAME)  # the hostile cases' frame: each is refused for its own fault
    scans = serialized(clouds)
    os.environ.update(dds_environment())  # before rclpy starts and the node process inherits it
    rclpy.init()
    node = start_node(NS, {"qos_reliability": "reliable"})
    probe = Probe(NS, reliable=True, name="soak_probe")
    try:
        soak = Soak(probe, scans, clouds, node.pid)
        _await_odometry(soak, probe, node)
        base = {key: probe.counter(key) for key in ("received", "queue_drops", "errors", "recoveries")}
        soak.published.clear()
        soak.unstamped = 0
        soak.bad.clear()
        verdicts0 = len(probe.verdicts)
        start = _stream(soak, probe, node, args)
        time.sleep(5.0)  # the queue drains, a last diagnostics report arrives
        return _summary(soak, probe, probe.verdicts[verdicts0:], base, start, args)
    finally:
        probe.close()
        node.terminate()
        node.wait(20)
        rclpy.try_shutdown()


def _await_odometry(soak: Soak, probe: Probe, node) -> None:
    """Scans every 0.5 s until the node answers (the engine loads, the kernels compile; 180 s at most)."""
    deadline = time.monotonic() + 180.0
    while not probe.odometry and time.monotonic() < deadline and node.poll() is None:
        soak.publish_scan()
        time.sleep(0.5)
    if not probe.odometry:
        raise RuntimeError("the node produced no odometry: " + node_log(node)[-2000:])
    time.sleep(2.0)


def _stream(soak: Soak, probe: Probe, node, args: argparse.Namespace) -> float:
    """Scans at RATE_HZ for ``args.minutes``, a fault every ``args.fault_every`` s in their place, the node's RSS
    every second and a progress line every 30 s. Returns the start (time.monotonic())."""
    start = time.monotonic()
    next_tick, next_fault, next_sample, next_print = start, start + args.fault_every, start, start
    k, end = 0, start + 60.0 * args.minutes
    while time.monotonic() < end:
        now = time.monotonic()
        if now >= next_fault:
            soak.inject(FAULTS[k % len(FAULTS)], now - start)
            k, next_fault = k + 1, now + args.fault_every
        else:
            soak.publish_scan()
        if now >= next_sample:
            soak.rss.append((now - start, rss_mb(node.pid)))
            next_sample += 1.0
        if now >= next_print:
            _progress(now - start, args.minutes, probe, soak)
            next_print += 30.0
        next_tick = max(next_tick + 1.0 / RATE_HZ, time.monotonic())  # no catch-up burst after a fault
        time.sleep(max(0.0, next_tick - time.monotonic()))
    return start


def _progress(elapsed: float, minutes: float, probe: Probe, soak: Soak) -> None:
    print(f"[soak] {elapsed / 60:.1f}/{minutes:.1f} min: {len(soak.published)} scans published, "
          f"{len(soak.faults)} faults, RSS {soak.rss[-1][1]:.0f} MB; node: drops {probe.counter('queue_drops')}, "
          f"errors {probe.counter('errors')}, global searches {probe.counter('recoveries')}, flagged "
          f"{probe.counter('flagged_steps')}, last: {probe.diagnostics.get('last_reason', '') or 'ok'}",
          file=sys.stderr, flush=True)


def _summary(soak: Soak, probe: Probe, verdicts: list, base: dict, start: float, args: argparse.Namespace) -> dict:
    by_stamp: dict[int, Any] = {}
    for v in verdicts:  # the first verdict on a stamp (a hostile duplicate stamp comes later)
        if v.stamp_ns in soak.published:
            by_stamp.setdefault(v.stamp_ns, v)
    latency = [(soak.published[s] - start, v.arrival - soak.published[s]) for s, v in by_stamp.items()]
    minutes = _latency_per_minute(latency)
    published = len(soak.published) + soak.unstamped
    received = probe.counter("received") - base["received"]
    drops = probe.counter("queue_drops") - base["queue_drops"]
    levels = [v.level for v in verdicts]
    rejected: dict[str, int] = {}
    for v in verdicts:
        if v.level == 2:
            rejected[v.rejected] = rejected.get(v.rejected, 0) + 1
    t, rss = np.array(soak.rss).T
    slope, slope_late = _slope(t, rss, min(WARM_UP_S, t[-1] / 2)), _slope(t, rss, t[-1] / 2)
    return {
        "minutes": args.minutes, "fault_every_s": args.fault_every, "published": published, "received": received,
        "verdicts": len(verdicts), "accepted": levels.count(0), "flagged": levels.count(1),
        "rejected": levels.count(2), "rejected_kinds": rejected, "queue_drops": drops,
        "unaccounted": published - len(verdicts) - drops,
        "node_errors": probe.counter("errors") - base["errors"],
        "recoveries": probe.counter("recoveries") - base["recoveries"],
        "bad_clouds_accepted": sorted(soak.bad[s] for s, v in by_stamp.items() if s in soak.bad and v.level == 0),
        "faults": {f: sum(1 for _, g, _ in soak.faults if g == f) for f in sorted(set(FAULTS))},
        "rss_mb": {"first": float(rss[0]), "last": float(rss[-1]), "min": float(rss.min()), "max": float(rss.max()),
                   "slope_mb_per_min_after_warm_up": slope, "slope_mb_per_min_second_half": slope_late},
        "latency_ms_per_minute": minutes, "rss_trace": soak.rss, "fault_log": soak.faults,
    }


def _slope(t: np.ndarray, rss: np.ndarray, after_s: float) -> float:
    """RSS growth (MB/min) fitted over the samples from ``after_s`` on."""
    use = t >= after_s
    return float(np.polyfit(t[use] / 60.0, rss[use], 1)[0]) if use.sum() > 2 else float("nan")


def _latency_per_minute(latency: list) -> list[dict]:
    out = []
    for minute in range(int(max((t for t, _ in latency), default=0) // 60) + 1):
        values = np.array([dt for t, dt in latency if minute * 60 <= t < (minute + 1) * 60]) * 1e3
        if len(values):
            p50, p95, p99 = np.percentile(values, [50, 95, 99])
            out.append({"minute": minute, "scans": len(values), "p50": float(p50), "p95": float(p95),
                        "p99": float(p99), "max": float(values.max())})
    return out


def _report(summary: dict) -> str:
    rss = summary["rss_mb"]
    lines = [f"soak: {summary['minutes']:.1f} min at {RATE_HZ:.0f} Hz, a fault every {summary['fault_every_s']:.0f} s "
             f"({', '.join(f'{k} {v}' for k, v in summary['faults'].items())})",
             f"messages: {summary['published']} published, {summary['received']} received by the node; verdicts "
             f"{summary['verdicts']} ({summary['accepted']} accepted, {summary['flagged']} flagged, "
             f"{summary['rejected']} rejected: {summary['rejected_kinds']}), {summary['queue_drops']} counted queue "
             f"drops, {summary['unaccounted']} unaccounted; {summary['node_errors']} processing errors, "
             f"{summary['recoveries']} global searches; bad clouds accepted as good steps: "
             f"{len(summary['bad_clouds_accepted'])} {summary['bad_clouds_accepted']}",
             f"RSS: {rss['first']:.0f} -> {rss['last']:.0f} MB (min {rss['min']:.0f}, max {rss['max']:.0f}); "
             f"slope after warm-up {rss['slope_mb_per_min_after_warm_up']:+.2f} MB/min, over the second half "
             f"{rss['slope_mb_per_min_second_half']:+.2f} MB/min",
             "| minute | scans | p50 ms | p95 ms | p99 ms | max ms |", "|---|---|---|---|---|---|"]
    lines += [f"| {m['minute']} | {m['scans']} | {m['p50']:.0f} | {m['p95']:.0f} | {m['p99']:.0f} | {m['max']:.0f} |"
              for m in summary["latency_ms_per_minute"]]
    return "\n".join(lines)


def _plot(summary: dict, path: Path) -> None:
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_rss, ax_lat) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    t, rss = np.array(summary["rss_trace"]).T
    ax_rss.plot(t / 60.0, rss)
    ax_rss.set_ylabel("node RSS (MB)")
    minutes = summary["latency_ms_per_minute"]
    x = [m["minute"] + 0.5 for m in minutes]
    for key in ("p50", "p95", "p99"):
        ax_lat.plot(x, [m[key] for m in minutes], marker="o", label=key)
    for t_fault, fault, _ in summary["fault_log"]:
        if fault in ("burst", "pause", "reset"):
            ax_lat.axvline(t_fault / 60.0, color="0.85", lw=0.5, zorder=0)
    ax_lat.set_ylabel("latency publish -> verdict (ms)")
    ax_lat.set_xlabel("minutes (grey: bursts, pauses, resets)")
    ax_lat.legend()
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    plt.close(fig)
    atomic_write_bytes(path, buffer.getvalue())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--fault-every", type=float, default=3.0, help="seconds between two faults")
    parser.add_argument("--out", type=Path, default=REPO / "results" / "soak")
    args = parser.parse_args()
    summary = run(args)
    print(_report(summary))
    write_report(args.out / "summary.json", json_text(summary, indent=2))
    _plot(summary, args.out / "soak.png")
    print(f"wrote {args.out / 'summary.json'} and {args.out / 'soak.png'}")


if __name__ == "__main__":
    main()
