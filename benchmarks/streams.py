"""Scans through a method: timed calls (an exception is a failed scan), and the step records they give."""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from benchmarks.metrics import relative_error
from cemnet_ros.data.scenes import COURTYARD_BOUNDS, LidarModel, courtyard_scene, lidar_scan, random_sensor_pose
from cemnet_ros.io.console import log

PERIOD_NS = 100_000_000  # 10 Hz
DT = PERIOD_NS * 1e-9


@dataclass
class Scan:
    """What a method returned for one delivered scan (pose None: the call raised ``error``)."""

    tick: int
    pose: Optional[np.ndarray]
    accepted: bool
    reason: str
    ms: float
    error: Optional[str]
    covariance: Optional[np.ndarray] = None


def run_scan(odometry, points: np.ndarray, stamp_ns: int, tick: int) -> Scan:
    """One timed call; an exception becomes a failed Scan with its message."""
    start = time.perf_counter()
    try:
        out = odometry.process(points, stamp_ns)
    except Exception as exc:  # noqa: BLE001 - the benchmark counts every failure
        return Scan(tick, None, False, "", 1e3 * (time.perf_counter() - start), f"{type(exc).__name__}: {exc}")
    return Scan(tick, out.pose, out.accepted, out.reason, 1e3 * (time.perf_counter() - start), None, out.covariance)


def run_stream(factory: Callable, max_range: float, scans: list[np.ndarray], ticks: list[int]) -> list[Scan]:
    """A fresh odometry over ``scans`` with stamps ``tick * 100 ms``; a failed construction fails every scan."""
    try:
        odometry = factory(max_range)
    except Exception as exc:  # noqa: BLE001
        return [Scan(t, None, False, "", 0.0, f"{type(exc).__name__}: {exc}") for t in ticks]
    return [run_scan(odometry, pts, t * PERIOD_NS, t) for pts, t in zip(scans, ticks)]


def warm_up(methods: dict[str, Callable]) -> None:
    """One small untimed pair through each method, so that no timed step pays for loading or JIT compiling."""
    scene, lidar, rng = courtyard_scene(), LidarModel(n_beams=16, n_azimuth=360), np.random.default_rng(0)
    pose = random_sensor_pose(COURTYARD_BOUNDS, rng, scene)
    scans = [lidar_scan(scene, pose, lidar, rng).astype(np.float64) for _ in range(2)]
    for name, factory in methods.items():
        log(f"warm-up: {name}")
        run_stream(factory, lidar.max_range, scans, [0, 1])


def scan_dicts(results: list[Scan]) -> list[dict]:
    """Per delivered scan: tick, pose (None: failed), accepted, reason, ms, error."""
    return [{"tick": s.tick, "pose": s.pose, "accepted": s.accepted, "reason": s.reason, "ms": s.ms,
             "error": s.error} for s in results]


def step_records(case: str, results: list[Scan], truth: dict[int, np.ndarray]) -> list[dict]:
    """One record per delivered scan after the first: its motion from the previous processed scan.

    A scan whose call raised, or that has no processed scan before it, is a failed step.
    """
    records, previous = [], None
    for k, scan in enumerate(results):
        if k and (scan.pose is None or previous is None):
            records.append(step_record(case, scan, None, None, scan.error or "no earlier scan was processed"))
        elif k:
            est = np.linalg.inv(previous.pose) @ scan.pose
            gt = np.linalg.inv(truth[previous.tick]) @ truth[scan.tick]
            records.append(step_record(case, scan, *relative_error(est, gt)))
        if scan.pose is not None:
            previous = scan
    return records


def step_record(case: str, scan: Scan, rte: Optional[float], rre: Optional[float],
                error: Optional[str] = None) -> dict:
    """The record of one step: case, index (tick), accepted, reason, errors (None: failed), ms, error."""
    error = error or scan.error
    return {"case": case, "index": scan.tick, "accepted": scan.accepted and error is None,
            "reason": error or scan.reason, "rte_m": rte, "rre_deg": rre, "ms": scan.ms, "error": error}
