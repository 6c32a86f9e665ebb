"""Ground-truth bags, the format of the bundled ones (``scripts/make_bags.py``): (points, T_world_sensor) frames as
``sensor_msgs/PointCloud2`` on ``/points`` and ``geometry_msgs/PoseStamped`` on ``/ground_truth``, same stamps."""
from __future__ import annotations

from pathlib import Path
from typing import Iterable

import numpy as np

from cemnet_ros.replay.bag_io import BagWriter

WORLD_FRAME = "world"


def write_bag(path: Path, frames: Iterable[tuple[np.ndarray, np.ndarray]], sensor_frame: str, period_ns: int,
              start_ns: int = 1_700_000_000_000_000_000) -> dict:
    """Write (points, T_world_sensor) frames as /points + /ground_truth; returns a small summary."""
    counts = []
    with BagWriter(path) as bag:
        for i, (points, pose) in enumerate(frames):
            stamp = start_ns + i * period_ns
            bag.write_cloud("/points", points, sensor_frame, stamp)
            bag.write_pose("/ground_truth", pose, WORLD_FRAME, stamp)
            counts.append(len(points))
    return {"bag": str(path), "scans": len(counts), "points_mean": int(np.mean(counts)), "bytes": path.stat().st_size}
