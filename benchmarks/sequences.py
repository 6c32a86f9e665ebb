"""The ``sequences`` set: drives (:mod:`.drives`) through each method; ATE, end drift and the events' outcomes.

Events: e = the first delivered scan after the event, a = the last delivered scan before it, candidates = the
first two delivered scans at or after e. recovered: a candidate is accepted and its pose relative to a is within
the precise tolerance of the truth; resumed: a candidate is accepted and its own step is within it; kidnap
flagged: scan e is not accepted.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from benchmarks.drives import Drive, make_drive
from benchmarks.metrics import (
    PRECISE_DEG,
    PRECISE_M,
    ate_first_pose,
    end_drift_percent,
    relative_error,
    summarize,
    within,
)
from benchmarks.streams import Scan, run_stream, scan_dicts, step_records
from cemnet_ros.data.scenes import LidarModel, courtyard_scene, lidar_scan
from cemnet_ros.io.console import log, progress


def event_outcome(event: dict, results: list[Scan], truth: list[np.ndarray]) -> dict:
    """recovered / resumed / flagged for one event (see the module docstring); None where the sequence ended too
    early."""
    processed = [s for s in results if s.pose is not None]
    before = [s for s in processed if s.tick < event["tick"]]
    after = [s for s in processed if s.tick >= event["tick"]][:2]
    out = {"kind": event["kind"], "tick": event["tick"], "recovered": None, "resumed": None, "flagged": None}
    if not before or not after:
        return out
    anchor = before[-1]
    previous = {s.tick: p for p, s in zip(processed, processed[1:])}

    def good(a: Scan, b: Scan) -> bool:
        est = np.linalg.inv(a.pose) @ b.pose
        return b.accepted and within(*relative_error(est, np.linalg.inv(truth[a.tick]) @ truth[b.tick]),
                                     PRECISE_M, PRECISE_DEG)

    out["recovered"] = any(good(anchor, s) for s in after)
    out["resumed"] = any(good(previous[s.tick], s) for s in after)
    out["flagged"] = after[0].tick == event["tick"] and not after[0].accepted
    return out


def sequence_metrics(drive: Drive, results: list[Scan]) -> dict:
    """ATE, end drift (whole drive and before the kidnap) and the events' outcomes of one method's run."""
    processed = [s for s in results if s.pose is not None]
    out = {"delivered": len(results), "failed": len(results) - len(processed), "ate_m": None, "drift_pct": None,
           "ate_before_kidnap_m": None, "drift_before_kidnap_pct": None,
           "events": [event_outcome(e, results, drive.poses) for e in drive.events]}
    before = [s for s in processed if drive.kidnap_tick is None or s.tick < drive.kidnap_tick]
    for suffix, part in (("", processed), ("_before_kidnap", before)):
        if len(part) < 2:
            continue
        est, gt = [s.pose for s in part], [drive.poses[s.tick] for s in part]
        distance = drive.odometer[part[-1].tick] - drive.odometer[part[0].tick]
        out[f"ate{suffix}_m"] = ate_first_pose(est, gt)
        out[f"drift{suffix}_pct"] = end_drift_percent(est, gt, distance)
    return out


def run_sequences(n: int, n_ticks: int, seed: int, methods: dict[str, Callable]) -> dict:
    """``n`` drives (seeds seed, seed + 1, ...), each through a fresh odometry of each method."""
    scene, lidar = courtyard_scene(), LidarModel()
    out: dict[str, dict] = {name: {"steps": [], "sequences": []} for name in methods}
    drives = []
    for k in range(n):
        rng = np.random.default_rng(seed + k)
        drive = make_drive(n_ticks, rng, scene)
        scans = [lidar_scan(scene, drive.poses[t], lidar, rng).astype(np.float64)
                 for t in progress(drive.delivered, f"sequences: ray-cast drive {k}")]
        drives.append({"seed": seed + k, "events": drive.events, **drive.extra, "delivered": drive.delivered,
                       "truth": [drive.poses[t] for t in drive.delivered]})
        for name, factory in methods.items():
            log(f"sequences: drive {k} ({len(scans)} scans) through {name}")
            results = run_stream(factory, lidar.max_range, scans, drive.delivered)
            out[name]["steps"] += step_records(f"seq{k}", results, dict(enumerate(drive.poses)))
            out[name]["sequences"].append({"seed": seed + k, **sequence_metrics(drive, results),
                                           "scans": scan_dicts(results)})
    for name in methods:
        out[name]["summary"] = summarize(out[name]["steps"])
    return {"drives": drives, "methods": out}
