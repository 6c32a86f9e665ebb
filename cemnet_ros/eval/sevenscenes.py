"""7-Scenes depth frames as the clouds of the paper's indoor protocol (CEMNet Sec. 4.3, Table 3).

The reference code (Jiang-HB/CEMNet ``datasets/process_dataset.py``) turns each 7Scene sample (a fragment
fused from consecutive depth frames, FMR's split: 296 train / 57 test, the test scene is office) into a
cloud by taking its points, scaling it by its bounding box's largest side and centring it on its mean
(``OnUnitCube``), and drawing 2048 of its points at random (``Resampler``). Pairs are then made exactly as
for ModelNet40 (:mod:`cemnet_ros.eval.protocol`: the first 1024 points, Euler angles U[0, 45 deg],
t U[-0.5, 0.5], shuffling, 768-point partial crops, no noise).

Here a cloud is one depth frame (``frames_per_cloud=1``) or several consecutive frames brought into the
first one's camera frame with their ground-truth poses; one point per ``voxel`` gives the even density of
the reference's mesh vertices before the same normalisation and resampling. These are choices: the paper's
fragments are TSDF-fused meshes of other 7-Scenes frames, which we do not have (docs/evaluation.md).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import List, Sequence, Tuple, Union

import numpy as np

from cemnet_ros.data.rgbd import DepthFrame, Intrinsics, depth_frames, depth_to_points, read_intrinsics
from cemnet_ros.schema import param, validate


@dataclass
class SevenScenesConfig:
    """How depth frames become the protocol's clouds."""

    frames_per_cloud: int = param(1, "consecutive depth frames fused (with their poses) into one cloud; 1 = each "
                                  "frame is one cloud", low=1)
    stride: int = param(1, "back-project every stride-th pixel in each direction", low=1)
    max_depth: float = param(4.0, "depths beyond this (m) are dropped", low=0.01)
    voxel: float = param(0.02, "one point per voxel of this size (m) before normalising (an even density); "
                         "0 = keep every point", low=0.0)
    n_resample: int = param(2048, "points drawn per cloud after normalising (the reference's Resampler)", low=3)
    seed: int = param(0, "cloud i is resampled with np.random.default_rng(seed + i)", low=0)

    def __post_init__(self) -> None:
        validate(self)


def on_unit_cube(points: np.ndarray) -> np.ndarray:
    """Scale by the bounding box's largest side, then centre on the mean (the reference's ``OnUnitCube``)."""
    points = np.asarray(points, dtype=np.float64)
    extent = float((points.max(axis=0) - points.min(axis=0)).max())
    if not extent > 0:
        raise ValueError("cannot normalise a cloud whose points all coincide")
    scaled = points / extent
    return scaled - scaled.mean(axis=0)


def resample(points: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` points in random order, each used once per pass (repeated only when the cloud has fewer than n)."""
    passes = [rng.permutation(len(points)) for _ in range(-(-n // len(points)))]
    return points[np.concatenate(passes)[:n]]


def fused_points(frames: Sequence[DepthFrame], intrinsics: Intrinsics, cfg: SevenScenesConfig) -> np.ndarray:
    """The frames' points in the first frame's camera frame, one point per ``cfg.voxel``."""
    from cemnet_ros.pipeline.steps.preprocess import voxel_downsample  # as data.kitti: only the filter

    T_first_world = np.linalg.inv(frames[0].T_world_camera)
    parts = []
    for frame in frames:
        T_first_camera = T_first_world @ frame.T_world_camera
        points = depth_to_points(frame.depth_m, intrinsics, cfg.stride, cfg.max_depth)
        parts.append(points @ T_first_camera[:3, :3].T + T_first_camera[:3, 3])
    return voxel_downsample(np.concatenate(parts), cfg.voxel)


def sevenscenes_clouds(root: Union[str, Path], cfg: SevenScenesConfig) -> Tuple[np.ndarray, List[str]]:
    """``points (S, n_resample, 3)`` float32 and one name per cloud (its first and last frame) from the
    disjoint windows of ``cfg.frames_per_cloud`` consecutive frames under ``root`` (a remainder is dropped)."""
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"7-Scenes folder not found: {root}")
    intrinsics = read_intrinsics(root)
    frames = list(depth_frames(root))
    n_clouds = len(frames) // cfg.frames_per_cloud
    if n_clouds == 0:
        raise ValueError(f"{root}: {len(frames)} frames, fewer than frames_per_cloud={cfg.frames_per_cloud}")
    clouds, names = [], []
    for i in range(n_clouds):
        window = frames[i * cfg.frames_per_cloud:(i + 1) * cfg.frames_per_cloud]
        points = fused_points(window, intrinsics, cfg)
        if len(points) < 3:
            raise ValueError(f"{root}: {window[0].name} has fewer than 3 valid depth pixels")
        clouds.append(resample(on_unit_cube(points), cfg.n_resample, np.random.default_rng(cfg.seed + i)))
        names.append(window[0].name if len(window) == 1 else f"{window[0].name}..{window[-1].name}")
    return np.stack(clouds).astype(np.float32), names
