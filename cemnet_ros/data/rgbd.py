"""RGB-D depth frames (7-Scenes layout) to point clouds in the camera's optical frame.

A folder holds ``camera-intrinsics.txt`` (the 3x3 K matrix) and ``rgbd-frames/frame-NNNNNN.depth.png``
(uint16 millimetres, 0 or 65535 = no reading) with ``frame-NNNNNN.pose.txt`` (4x4 camera-to-world,
``T_world_camera``). Back-projection: ``x = (u - cx) z / fx``, ``y = (v - cy) z / fy`` (x right, y down,
z forward). The bundled bag (``scripts/make_bags.py``) and the 7-Scenes evaluation (``eval/sevenscenes.py``)
both read frames through this module.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Tuple, Union

import numpy as np

from cemnet_ros.io.optional import optional_module

INVALID_DEPTH_MM = (0, 65535)  # 7-Scenes marks pixels without a reading with either value
INTRINSICS_FILE = "camera-intrinsics.txt"
FRAMES_DIR = "rgbd-frames"


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics of the depth camera (pixels)."""

    fx: float
    fy: float
    cx: float
    cy: float


KINECT_7SCENES = Intrinsics(585.0, 585.0, 320.0, 240.0)  # the 7-Scenes depth camera


@dataclass(frozen=True)
class DepthFrame:
    """One depth image in metres (0 = no reading) and the camera's pose in the world."""

    name: str  # e.g. "frame-000008"
    depth_m: np.ndarray  # (h, w) float64
    T_world_camera: np.ndarray  # (4, 4)


def read_intrinsics(root: Union[str, Path]) -> Intrinsics:
    """The K matrix in ``root/camera-intrinsics.txt``, or the 7-Scenes Kinect's when the file is absent."""
    path = Path(root) / INTRINSICS_FILE
    if not path.exists():
        return KINECT_7SCENES
    k = np.loadtxt(path)
    if k.shape != (3, 3) or not np.isfinite(k).all() or k[0, 0] <= 0 or k[1, 1] <= 0:
        raise ValueError(f"{path}: expected a 3x3 camera matrix with positive focal lengths")
    return Intrinsics(float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2]))


def read_depth_png(path: Union[str, Path]) -> np.ndarray:
    """A uint16 millimetre depth PNG as metres (float64), pixels without a reading set to 0."""
    Image = optional_module("PIL.Image", "reading 7-Scenes depth PNGs")  # MissingOptional without Pillow

    with Image.open(path) as image:
        raw = np.asarray(image)
    if raw.ndim != 2 or raw.dtype != np.uint16:
        raise ValueError(f"{path}: expected a single-channel 16-bit depth image, got {raw.dtype} {raw.shape}")
    depth = raw.astype(np.float64) / 1000.0
    depth[np.isin(raw, INVALID_DEPTH_MM)] = 0.0
    return depth


def depth_to_points(depth_m: np.ndarray, intrinsics: Intrinsics, stride: int = 1,
                    max_depth: float = np.inf) -> np.ndarray:
    """Back-project every ``stride``-th pixel (rows and columns) with a depth in (0, max_depth] metres.

    Returns (n, 3) float64 points in the camera's optical frame, in row-major pixel order.
    """
    if stride < 1:
        raise ValueError(f"stride must be >= 1, got {stride}")
    depth = np.asarray(depth_m, dtype=np.float64)[::stride, ::stride]
    v, u = np.mgrid[0:depth.shape[0] * stride:stride, 0:depth.shape[1] * stride:stride]
    valid = (depth > 0) & (depth <= max_depth)
    z = depth[valid]
    return np.stack([(u[valid] - intrinsics.cx) * z / intrinsics.fx,
                     (v[valid] - intrinsics.cy) * z / intrinsics.fy, z], axis=-1)


def depth_frames(root: Union[str, Path]) -> Iterator[DepthFrame]:
    """Every ``rgbd-frames/*.depth.png`` under ``root`` in name order, with its ``.pose.txt``."""
    folder = Path(root) / FRAMES_DIR
    pngs = sorted(folder.glob("frame-*.depth.png"))
    if not pngs:
        raise FileNotFoundError(f"no frame-*.depth.png in {folder}")
    for png in pngs:
        name = png.name[:-len(".depth.png")]
        pose = np.loadtxt(png.with_name(name + ".pose.txt"))
        if pose.shape != (4, 4) or not np.isfinite(pose).all():
            raise ValueError(f"{png.with_name(name + '.pose.txt')}: expected a finite 4x4 pose")
        yield DepthFrame(name, read_depth_png(png), pose)


def rgbd_frames(root: Union[str, Path], stride: int, voxel: float, max_depth: float
                ) -> Iterator[Tuple[np.ndarray, np.ndarray]]:
    """Yield (points (n, 3) in the camera optical frame, T_world_camera) per frame: back-projected every
    ``stride``-th pixel up to ``max_depth`` m, one point per ``voxel`` m voxel (the centroid)."""
    from cemnet_ros.pipeline.steps.preprocess import voxel_downsample  # as kitti_frames: only the filter

    intrinsics = read_intrinsics(root)
    for frame in depth_frames(root):
        points = depth_to_points(frame.depth_m, intrinsics, stride, max_depth)
        yield voxel_downsample(points, voxel), frame.T_world_camera
