"""The scans of a bag, read once for training: the node's range crop and voxel grid (metres, sensor frame), the
scale that makes network units, and the bag's ground truth when it has one.

The scale is measured as the node measures it (the robust radius of the first usable scan, unless
``preprocess.scale`` fixes it), so the clouds the network sees while training are those it sees in the node.
Scans are used as recorded: no deskewing (the node deskews scans that carry per-point times).
"""
from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from typing import Optional

import numpy as np
from tqdm import tqdm

from cemnet_ros.pipeline.config import PreprocessConfig
from cemnet_ros.pipeline.errors import ScanRejected
from cemnet_ros.pipeline.steps.frame import cropped, measured_scale, voxel_cloud, voxel_size
from cemnet_ros.replay.bag_io import BagReader, SkippedMessage


@dataclass
class ScanSet:
    """Voxel clouds of consecutive scans and what turns them into pairs."""

    clouds: list[np.ndarray]  # (n_i, 3) float32, metres, sensor frame
    poses: Optional[np.ndarray]  # (n, 4, 4) T_world_sensor from the bag's ground truth; None without
    scale: float  # metres per network unit

    def __len__(self) -> int:
        return len(self.clouds)

    def part(self, indices: np.ndarray) -> "ScanSet":
        """The scans at ``indices`` (in that order), same scale."""
        poses = None if self.poses is None else self.poses[indices]
        return ScanSet([self.clouds[i] for i in indices], poses, self.scale)

    def relative(self, target: int, source: int) -> Optional[np.ndarray]:
        """T_target_source (4x4, m) between two scans' sensor frames: the identity for one scan, None when two
        scans have no ground truth."""
        if target == source:
            return np.eye(4)
        if self.poses is None:
            return None
        return np.linalg.inv(self.poses[target]) @ self.poses[source]


def read_bag_scans(path: str | os.PathLike, topic: str, config: PreprocessConfig, progress: bool = True) -> ScanSet:
    """Every usable scan of ``topic`` ('' = the bag's only PointCloud2 topic), prepared up to the voxel cloud; a
    message that cannot be decoded or a scan the node would reject is skipped with a warning."""
    clouds: list[np.ndarray] = []
    stamps: list[int] = []
    scale: Optional[float] = None
    with BagReader(path, topic or None) as reader:
        for item in tqdm(reader.scans(), total=reader.info.n_clouds, desc="reading scans", disable=not progress):
            if isinstance(item, SkippedMessage):
                warnings.warn(f"skipping {item.topic} message {item.index}: {item.reason}")
                continue
            try:
                kept = cropped(item.points, config)
                item_scale = scale if scale is not None else config.scale if config.scale > 0 else measured_scale(kept)
                clouds.append(voxel_cloud(kept, config, voxel_size(config, item_scale)).astype(np.float32))
            except ScanRejected as err:
                warnings.warn(f"skipping {reader.info.cloud_topic} message {item.index}: {err}")
                continue
            scale = item_scale  # the first used scan fixes the units, as in the node
            stamps.append(item.stamp_ns)
        gt_stamps, gt_poses, _ = reader.ground_truth()
    if scale is None or len(clouds) < 2:
        raise ValueError(f"{path}: {len(clouds)} usable scan(s); training needs at least 2")
    return ScanSet(clouds, poses_at(stamps, gt_stamps, gt_poses), scale)


def poses_at(stamps: list[int], gt_stamps: np.ndarray, gt_poses: np.ndarray) -> Optional[np.ndarray]:
    """The ground-truth pose stamped exactly as each scan; None when any scan has none (the truth is then unknown
    for pairs of two scans; training needs none)."""
    by_stamp = dict(zip(gt_stamps.tolist(), gt_poses))
    if not by_stamp:
        return None
    missing = [s for s in stamps if s not in by_stamp]
    if missing:
        warnings.warn(f"{len(missing)} of {len(stamps)} scans have no ground truth at their stamp: pairs of two "
                      "scans get no truth")
        return None
    return np.stack([by_stamp[s] for s in stamps])


def split_in_time(n: int, val_fraction: float) -> tuple[np.ndarray, np.ndarray]:
    """(train, val) index ranges: validation takes the last round(n * val_fraction) >= 1 scans, so that no
    validation scan has a near-identical neighbour among the training scans (except at the one boundary)."""
    if n < 2:
        raise ValueError(f"need at least 2 scans to hold some out for validation, got {n}")
    n_val = min(n - 1, max(1, int(round(n * val_fraction))))
    return np.arange(n - n_val), np.arange(n - n_val, n)
