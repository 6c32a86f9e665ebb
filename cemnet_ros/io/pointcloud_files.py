"""Read point clouds from common files into ``(n, 3) float64`` arrays; write binary PLY or PCD.

Supported: ``.ply`` (ascii, binary little/big endian; ply.py), ``.pcd`` (ascii, binary, binary_compressed;
pcd.py), ``.npy`` / ``.npz`` (key ``points`` or the single array; first 3 columns) and KITTI ``.bin`` (float32
x, y, z, reflectance; arrays.py). Only x, y, z are kept. Rows with NaN/inf are dropped with a warning. A
missing file raises ``FileNotFoundError``; any other bad input (empty, truncated, malformed, no usable point)
raises :class:`PointCloudFileError`, a ValueError whose message names the file and the problem.
:func:`write_points` writes ``.pcd`` (binary, as PCL, CloudCompare and Autoware load it) or ``.ply`` (binary
little endian), by the path's suffix.
"""
from __future__ import annotations

import warnings
from pathlib import Path
from typing import Callable, Dict

import numpy as np

from cemnet_ros.io.arrays import read_kitti_bin, read_npy, read_npz
from cemnet_ros.io.atomic import PathLike
from cemnet_ros.io.cloud_format import PointCloudFileError
from cemnet_ros.io.lzf import lzf_decompress
from cemnet_ros.io.pcd import read_pcd, write_pcd
from cemnet_ros.io.ply import read_ply, write_ply

__all__ = ["PointCloudFileError", "read_points", "write_points", "write_ply", "write_pcd", "lzf_decompress"]

_READERS: Dict[str, Callable[[Path, bytes], np.ndarray]] = {
    ".ply": read_ply, ".pcd": read_pcd, ".npy": read_npy, ".npz": read_npz, ".bin": read_kitti_bin,
}

_WRITERS: Dict[str, Callable[[PathLike, np.ndarray], Path]] = {".pcd": write_pcd, ".ply": write_ply}
WRITTEN_SUFFIXES = tuple(_WRITERS)


def write_points(path: PathLike, points: np.ndarray) -> Path:
    """Write ``(n, 3)`` points (float32 x, y, z) atomically, as binary PCD or PLY by the suffix of ``path``
    (``.pcd``, ``.ply``, any case); ValueError for another suffix. The folder must exist."""
    suffix = Path(path).suffix.lower()
    writer = _WRITERS.get(suffix)
    if writer is None:
        raise ValueError(f"unknown point cloud suffix {suffix!r} in {path}: use {' or '.join(WRITTEN_SUFFIXES)}")
    return writer(path, points)


def read_points(path: PathLike) -> np.ndarray:
    """Read the x, y, z of every point in ``path`` as an ``(n, 3) float64`` array (finite rows only)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"point cloud file not found: {path}")
    if not path.is_file():
        raise PointCloudFileError(path, "not a regular file")
    suffix = path.suffix.lower()
    reader = _READERS.get(suffix)
    if reader is None:
        raise PointCloudFileError(path, f"unknown point cloud extension {suffix!r}; "
                                        f"supported: {', '.join(sorted(_READERS))}")
    raw = path.read_bytes()
    if not raw:
        raise PointCloudFileError(path, "empty file (0 bytes)")
    points = np.asarray(reader(path, raw), dtype=np.float64)
    return _finite_rows(points, path)


def _finite_rows(points: np.ndarray, path: Path) -> np.ndarray:
    """The rows with finite x, y, z (a warning counts the others); an error when none is left."""
    if points.ndim != 2 or points.shape[1] != 3 or len(points) == 0:
        raise PointCloudFileError(path, f"expected (n, 3) points with n >= 1, got shape {points.shape}")
    finite = np.isfinite(points[:, 0]) & np.isfinite(points[:, 1]) & np.isfinite(points[:, 2])  # 5x .all(axis=1)
    n_bad = int((~finite).sum())
    if n_bad == len(points):
        raise PointCloudFileError(path, f"contains no (finite) points: all {n_bad} have NaN or inf coordinates")
    if n_bad:
        warnings.warn(f"{path}: dropped {n_bad} of {len(points)} points with non-finite coordinates",
                      stacklevel=3)
        points = points[finite]
    return points
