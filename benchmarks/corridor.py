"""The ``corridor`` set: a drive at 1.5 m/s along a featureless corridor (x unobservable): is it flagged, how much
of the along-corridor motion comes back, and does the covariance say x is the uncertain axis?"""
from __future__ import annotations

from typing import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from benchmarks.metrics import summarize
from benchmarks.streams import DT, Scan, run_stream, step_records
from cemnet_ros.data.scenes import LidarModel, corridor_scene, lidar_scan
from cemnet_ros.io.console import log

CORRIDOR_LIDAR = LidarModel(max_range=40.0)  # the open ends (60 m away) stay out of range
CORRIDOR_SPEED = 1.5  # m/s
CORRIDOR_MAX_SCANS = int(2 * (60.0 - CORRIDOR_LIDAR.max_range) / (CORRIDOR_SPEED * DT))  # ends (+-60 m) unseen


def corridor_drive(n: int) -> list[np.ndarray]:
    """Straight drive along the corridor axis around x = 0 with a small sway (+-0.1 m) and yaw wobble (+-1 deg)."""
    poses = []
    for i in range(n):
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_euler("z", np.radians(1.0) * np.sin(0.3 * i)).as_matrix()
        pose[:3, 3] = (i - n / 2) * CORRIDOR_SPEED * DT, 0.1 * np.sin(0.2 * i), 1.5
        poses.append(pose)
    return poses


def corridor_metrics(results: list[Scan], truth: list[np.ndarray]) -> dict:
    """Flagged fraction, along-corridor motion recovered, and the covariance's x (along) vs y (across) std."""
    processed = [s for s in results if s.pose is not None]
    steps = processed[1:]
    out = {"flagged_fraction": sum(not s.accepted for s in steps) / len(steps) if steps else None,
           "along_recovered": None, "x_std_median_m": None, "y_std_median_m": None, "x_over_y_std_median": None,
           "x_std_larger_fraction": None}
    if len(processed) >= 2:
        est = np.linalg.inv(processed[0].pose) @ processed[-1].pose
        gt = np.linalg.inv(truth[processed[0].tick]) @ truth[processed[-1].tick]
        out["along_recovered"] = float(est[0, 3] / gt[0, 3])
    covs = [s.covariance for s in steps if s.covariance is not None]
    if covs:
        x_std = np.sqrt([c[0, 0] for c in covs])
        y_std = np.sqrt([c[1, 1] for c in covs])
        out.update(x_std_median_m=float(np.median(x_std)), y_std_median_m=float(np.median(y_std)),
                   x_over_y_std_median=float(np.median(x_std / y_std)),
                   x_std_larger_fraction=float(np.mean(x_std > y_std)),
                   x_std_per_step_m=x_std.tolist(), y_std_per_step_m=y_std.tolist())
    return out


def run_corridor(n: int, seed: int, methods: dict[str, Callable]) -> dict:
    """A drive along ``corridor_scene()`` at 1.5 m/s through a fresh odometry of each method."""
    scene, rng, poses = corridor_scene(), np.random.default_rng(seed), corridor_drive(n)
    scans = [lidar_scan(scene, p, CORRIDOR_LIDAR, rng).astype(np.float64) for p in poses]
    out = {}
    for name, factory in methods.items():
        log(f"corridor: {n} scans through {name}")
        results = run_stream(factory, CORRIDOR_LIDAR.max_range, scans, list(range(n)))
        steps = step_records("corridor", results, dict(enumerate(poses)))
        out[name] = {"summary": summarize(steps), "steps": steps, **corridor_metrics(results, poses)}
    return out
