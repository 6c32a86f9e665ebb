#!/usr/bin/env python3
"""The ray-cast bags the package's scan weights are trained on (``cemnet_ros/weights/scan.npz``).

One bag per sensor model, each of ``--scans`` courtyard scans (``cemnet_ros.data.scenes``) from random poses in free
space (yaw uniform, +-0.1 m height, +-1 deg tilt; seeded per bag, seeds 100 + k, apart from the robustness
benchmark's seeds 0, 1), with ground truth:

    lidar16   16 beams, -15..+15 deg (a VLP-16's fan), 900 azimuth steps
    lidar32   32 beams, -25..+15 deg (the bundled synthetic bag's sensor), 1000 steps
    lidar64   64 beams, -25..+3 deg (an HDL-64-like fan), 1000 steps
    lidar128 128 beams, -25..+15 deg, 1024 steps

    python scripts/scan_training_bags.py --out results/scan_bags
    cemnet-train --bag results/scan_bags/lidar16.mcap,...,bags/kitti_00_6scans.mcap --objective known_motion ...

The exact training command of the shipped weights is in docs/training.md and in the weights' metadata.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # runnable from a fresh checkout without `pip install`
    sys.path.insert(0, str(REPO))

from cemnet_ros.data.bags import write_bag  # noqa: E402
from cemnet_ros.data.scenes import (  # noqa: E402
    COURTYARD_BOUNDS,
    LidarModel,
    courtyard_scene,
    lidar_scan,
    random_sensor_pose,
)
from cemnet_ros.io.console import log  # noqa: E402

SENSORS = {"lidar16": LidarModel(n_beams=16, n_azimuth=900, elevation_deg=(-15.0, 15.0)),
           "lidar32": LidarModel(n_beams=32, n_azimuth=1000, elevation_deg=(-25.0, 15.0)),
           "lidar64": LidarModel(n_beams=64, n_azimuth=1000, elevation_deg=(-25.0, 3.0)),
           "lidar128": LidarModel(n_beams=128, n_azimuth=1024, elevation_deg=(-25.0, 15.0))}
FIRST_SEED = 100
PERIOD_NS = 100_000_000


def frames(lidar: LidarModel, n: int, seed: int):
    """``n`` (scan, T_world_sensor) of the courtyard from random free-space poses."""
    scene, rng = courtyard_scene(), np.random.default_rng(seed)
    for _ in range(n):
        pose = random_sensor_pose(COURTYARD_BOUNDS, rng, scene)
        yield lidar_scan(scene, pose, lidar, rng), pose


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "results" / "scan_bags", help="output folder")
    parser.add_argument("--scans", type=int, default=60, help="scans per bag (default 60)")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    for k, (name, lidar) in enumerate(SENSORS.items()):
        summary = write_bag(args.out / f"{name}.mcap", frames(lidar, args.scans, FIRST_SEED + k), name, PERIOD_NS)
        log(f"{summary['bag']}: {summary['scans']} scans, {summary['points_mean']} points each on average")
    return 0


if __name__ == "__main__":
    sys.exit(main())
