"""Scan preprocessing before registration: drop non-finite points, range crop, voxel grid, fixed-size subset.

Everything here is in metres; :func:`robust_radius` gives the scale that maps a scan to network units (the
network and the CEM's epsilon live on the ModelNet unit sphere).
"""
from __future__ import annotations

import numpy as np

SAMPLING_METHODS = ("random", "farthest")


def finite_points(points: np.ndarray) -> np.ndarray:
    """(n, 3) float64 rows whose three coordinates are all finite."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), not {pts.shape}")
    return pts[np.isfinite(pts).all(axis=1)]


def crop_range(points: np.ndarray, min_range: float = 0.0, max_range: float = 0.0) -> np.ndarray:
    """Keep points whose distance to the sensor origin lies in [min_range, max_range]; 0 disables a bound."""
    if min_range <= 0.0 and max_range <= 0.0:
        return points
    dist = np.linalg.norm(points, axis=1)
    keep = np.ones(len(points), dtype=bool)
    if min_range > 0.0:
        keep &= dist >= min_range
    if max_range > 0.0:
        keep &= dist <= max_range
    return points[keep]


def voxel_downsample(points: np.ndarray, voxel_size: float) -> np.ndarray:
    """One point per occupied voxel: the centroid of the points inside it (voxel_size <= 0 = unchanged)."""
    if voxel_size <= 0.0 or len(points) == 0:
        return points
    cells = np.floor(points / voxel_size).astype(np.int64)
    cells -= cells.min(0)
    dims = cells.max(0) + 1
    keys = (cells[:, 0] * dims[1] + cells[:, 1]) * dims[2] + cells[:, 2]  # one int64 per voxel: a fast sort
    order = np.argsort(keys)
    sorted_keys = keys[order]
    starts = np.flatnonzero(np.r_[True, sorted_keys[1:] != sorted_keys[:-1]])
    sums = np.add.reduceat(points[order], starts, axis=0)
    counts = np.diff(np.r_[starts, len(points)])
    return sums / counts[:, None]


def farthest_point_indices(points: np.ndarray, n: int, start: int = 0) -> np.ndarray:
    """Greedy farthest-point sampling: ``n`` indices spread evenly over the cloud."""
    chosen = np.empty(n, dtype=np.int64)
    chosen[0] = start
    dist = np.full(len(points), np.inf)
    for i in range(1, n):
        dist = np.minimum(dist, np.sum((points - points[chosen[i - 1]]) ** 2, axis=1))
        chosen[i] = int(np.argmax(dist))
    return chosen


def subsample(points: np.ndarray, n: int, method: str = "random", seed: int = 0) -> np.ndarray:
    """At most ``n`` points: a seeded random subset (reproducible) or farthest-point sampling."""
    if method not in SAMPLING_METHODS:
        raise ValueError(f"sampling must be one of {SAMPLING_METHODS}, not {method!r}")
    if len(points) <= n:
        return points
    if method == "farthest":
        return points[farthest_point_indices(points, n)]
    rng = np.random.default_rng(seed)
    return points[np.sort(rng.choice(len(points), size=n, replace=False))]


def robust_radius(points: np.ndarray, percentile: float = 90.0, max_samples: int = 20000) -> float:
    """The ``percentile`` of distances to the median point: a scan's size that ignores a few far outliers."""
    if len(points) == 0:
        raise ValueError("cannot measure the radius of an empty cloud")
    if len(points) > max_samples:
        points = points[np.random.default_rng(0).choice(len(points), size=max_samples, replace=False)]
    centred = points - np.median(points, axis=0)
    return float(np.percentile(np.linalg.norm(centred, axis=1), percentile))

