"""The weight files that ship with the package and their names, without torch: the node checks a weights
parameter against them before the engine (and torch) loads in the background (:mod:`.checkpoint` reads them)."""
from __future__ import annotations

from pathlib import Path

PACKAGE_WEIGHTS_DIR = Path(__file__).resolve().parents[1] / "weights"
# The weights `register` uses when none are given: this project's, trained by cemnet-train on the ModelNet40
# subset (see cemnet_ros/weights/README.md). The official clean checkpoint, converted, ships beside them.
DEFAULT_WEIGHTS = PACKAGE_WEIGHTS_DIR / "cemnet_ros_modelnet40_clean.npz"
OFFICIAL_WEIGHTS = PACKAGE_WEIGHTS_DIR / "official_modelnet40_clean.npz"
# Trained on LiDAR scans for the node's recovery (ray-cast courtyard scans of 16-128 beams and the 6 KITTI scans).
SCAN_WEIGHTS = PACKAGE_WEIGHTS_DIR / "cemnet_ros_lidar_scans.npz"
NAMED_WEIGHTS = {"": DEFAULT_WEIGHTS, "official": OFFICIAL_WEIGHTS, "scan": SCAN_WEIGHTS}
