#!/usr/bin/env python3
"""Make the bundled rosbag2 (mcap) replay bags: a ray-cast synthetic LiDAR run, 6 KITTI scans, 50 7-Scenes frames.

Every bag holds ``sensor_msgs/msg/PointCloud2`` scans (float32 x, y, z, little endian; header.frame_id = the
sensor frame) on ``/points`` and ``geometry_msgs/msg/PoseStamped`` ground truth (sensor pose in the world
frame, same stamps) on ``/ground_truth``. Output is deterministic (seeded) and written atomically.

    python scripts/make_bags.py                      # all bags into bags/ (KITTI/7-Scenes need ../shared)
    python scripts/make_bags.py synthetic --out bags # only the synthetic bag (no external data needed)
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # runnable from a fresh checkout without `pip install`
    sys.path.insert(0, str(REPO))

from benchmarks import shared  # noqa: E402
from cemnet_ros.data.bags import write_bag  # noqa: E402
from cemnet_ros.data.kitti import kitti_frames  # noqa: E402
from cemnet_ros.data.rgbd import rgbd_frames  # noqa: E402
from cemnet_ros.data.scenes import LidarModel, courtyard_scene, lidar_scan, synthetic_trajectory  # noqa: E402

SHARED = shared.SHARED / "data"


# ----------------------------------------------------------------------------------------------------------
# Bags (the format: cemnet_ros.data.bags)
# ----------------------------------------------------------------------------------------------------------
BAG_NAMES = {"synthetic": "synthetic_lidar.mcap", "kitti": "kitti_00_6scans.mcap", "rgbd": "rgbd_7scenes_50.mcap"}


def make_synthetic(out: Path, n_scans: int = 20, seed: int = 0) -> dict:
    scene, lidar = courtyard_scene(), LidarModel()
    rng = np.random.default_rng(seed)
    frames = ((lidar_scan(scene, pose, lidar, rng), pose) for pose in synthetic_trajectory(n_scans))
    return write_bag(out / BAG_NAMES["synthetic"], frames, "lidar", 100_000_000)


def make_kitti(out: Path, crop: float = 50.0, voxel: float = 0.2) -> dict:
    frames = kitti_frames(SHARED / "kitti_sample", crop, voxel)
    return write_bag(out / BAG_NAMES["kitti"], frames, "velodyne", 100_000_000)


def make_rgbd(out: Path, stride: int = 2, voxel: float = 0.02, max_depth: float = 4.0) -> dict:
    frames = rgbd_frames(SHARED / "rgbd_7scenes", stride, voxel, max_depth)
    return write_bag(out / BAG_NAMES["rgbd"], frames, "camera_depth_optical_frame", 33_333_333)


MAKERS = {"synthetic": make_synthetic, "kitti": make_kitti, "rgbd": make_rgbd}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("which", nargs="*", help=f"bags to make: {', '.join(MAKERS)} (default: all)")
    parser.add_argument("--out", type=Path, default=REPO / "bags", help="output directory (default: bags/)")
    parser.add_argument("--force", action="store_true", help="overwrite existing bags")
    args = parser.parse_args(argv)
    unknown = sorted(set(args.which) - set(MAKERS))
    if unknown:
        parser.error(f"unknown bag(s) {unknown}; choose from {list(MAKERS)}")
    args.out.mkdir(parents=True, exist_ok=True)
    for name in args.which or list(MAKERS):
        target = args.out / BAG_NAMES[name]
        if name != "synthetic" and not SHARED.exists():
            print(f"skip {name}: {SHARED} not found (needed for the real data)")
            continue
        if target.exists() and not args.force:
            print(f"skip {name}: {target} exists (use --force to rebuild)")
            continue
        target.unlink(missing_ok=True)
        info = MAKERS[name](args.out)
        print(f"{name}: {info['scans']} scans, {info['points_mean']} points/scan, "
              f"{info['bytes'] / 1e6:.2f} MB -> {info['bag']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
