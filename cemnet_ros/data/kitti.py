"""KITTI odometry sample loader: velodyne ``.bin`` scans, ``poses.txt`` (camera 0) and ``calib.txt`` (``Tr``).

Ground truth is returned for the velodyne frame, with world = the first velodyne frame:
``T_world_velo_k = Tr^-1 @ P_k @ Tr`` (``P_k`` the camera pose, ``Tr`` velodyne -> camera 0).
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterator

import numpy as np


def _se3(rows: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :4] = np.asarray(rows, dtype=np.float64).reshape(3, 4)
    return out


def kitti_scans(root: Path) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Yield (full-resolution points (n,3) float32 in the velodyne frame, T_world_velo) per scan."""
    root = Path(root)
    tr = None
    for line in (root / "calib.txt").read_text().splitlines():
        if line.startswith("Tr:"):
            tr = _se3([float(v) for v in line.split()[1:]])
    if tr is None:
        raise ValueError(f"{root / 'calib.txt'} has no 'Tr:' line")
    tr_inv = np.linalg.inv(tr)
    poses = [_se3([float(v) for v in ln.split()]) for ln in (root / "poses.txt").read_text().splitlines() if ln.strip()]
    scans = sorted((root / "velodyne").glob("*.bin"))
    if len(scans) != len(poses):
        raise ValueError(f"{len(scans)} scans but {len(poses)} poses in {root}")
    for scan, cam_pose in zip(scans, poses):
        yield np.fromfile(scan, dtype=np.float32).reshape(-1, 4)[:, :3], tr_inv @ cam_pose @ tr


def kitti_frames(root: Path, crop: float, voxel: float) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Yield (points (n,3) float32 in the velodyne frame, T_world_velo): cropped to ``crop`` m, voxel-filtered."""
    from cemnet_ros.pipeline.steps.preprocess import voxel_downsample  # here: reading raw scans needs no pipeline

    for pts, pose in kitti_scans(root):
        pts = pts[np.linalg.norm(pts, axis=1) <= crop]
        yield voxel_downsample(pts, voxel), pose
