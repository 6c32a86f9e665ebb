"""The ``fast_gaps`` set: a car crossing the courtyard at 15-25 m/s (10 Hz, a gentle weave) with one gap of
0.5-1 s in which it keeps its speed or brakes: is the gap carried, is what cannot be vouched for flagged, and how
far off does each method end?"""
from __future__ import annotations

from typing import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from benchmarks.metrics import ate_first_pose, summarize
from benchmarks.streams import DT, run_stream, step_records
from cemnet_ros.data.scenes import LidarModel, courtyard_scene, lidar_scan
from cemnet_ros.io.console import log

SPEEDS = (15.0, 25.0)  # m/s
GAPS = (0.5, 1.0)  # s
MAX_BRAKE = 6.0  # m/s^2, in the gap (half of the drives keep their speed)
LANE = (-16.0, 46.0, 0.0)  # x from, x to, y: a lane clear of the courtyard's obstacles
LEAD_TICKS = 6  # delivered ticks before the gap
LIDAR = LidarModel()


def fast_drive(rng: np.random.Generator) -> tuple[list[np.ndarray], list[int], dict]:
    """Every tick's true pose along the lane, the delivered ticks (the gap left out) and the draw."""
    speed, gap = rng.uniform(*SPEEDS), int(round(rng.uniform(*GAPS) / DT))
    brake = rng.uniform(0.0, MAX_BRAKE) if rng.random() < 0.5 else 0.0
    poses, x, tick = [], LANE[0], 0
    while x <= LANE[1]:
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_euler("zyx", [0.02 * np.sin(0.3 * tick), 0.01 * np.sin(0.5 * tick),
                                                   0.01 * np.cos(0.4 * tick)]).as_matrix()
        pose[:3, 3] = x, LANE[2] + 0.1 * np.sin(0.2 * tick), 1.8
        poses.append(pose)
        braked_ticks = min(max(tick - LEAD_TICKS, 0), gap)  # it brakes in the gap, then keeps that speed
        x, tick = x + max(speed - brake * DT * braked_ticks, 1.0) * DT, tick + 1
    delivered = [t for t in range(len(poses)) if not LEAD_TICKS <= t < LEAD_TICKS + gap]
    return poses, delivered, {"speed_mps": speed, "gap_s": gap * DT, "brake_mps2": brake}


def run_fast_gaps(n: int, seed: int, methods: dict[str, Callable]) -> dict:
    """``n`` drives (seeds ``seed``, ``seed + 1``, ...) through a fresh odometry of each method: the step
    summary over all drives, and per drive its draw, ATE and the steps flagged."""
    scene, drives = courtyard_scene(), []
    for k in range(n):
        rng = np.random.default_rng(seed + k)
        poses, ticks, draw = fast_drive(rng)
        drives.append((poses, ticks, draw, [lidar_scan(scene, poses[t], LIDAR, rng).astype(np.float64)
                                            for t in ticks]))
    out = {}
    for name, factory in methods.items():
        log(f"fast_gaps: {n} drives through {name}")
        steps, per_drive = [], []
        for k, (poses, ticks, draw, scans) in enumerate(drives):
            results = run_stream(factory, LIDAR.max_range, scans, ticks)
            records = step_records(f"fast {k}", results, dict(enumerate(poses)))
            processed = [s for s in results if s.pose is not None]
            ate = ate_first_pose([s.pose for s in processed], [poses[s.tick] for s in processed]) if processed \
                else None
            per_drive.append({**draw, "ate_m": ate, "flagged": sum(not r["accepted"] for r in records)})
            steps += records
        out[name] = {"summary": summarize(steps), "steps": steps, "drives": per_drive}
    return out
