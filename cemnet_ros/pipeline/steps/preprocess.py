"""Scan preprocessing before registration: drop non-finite points, range crop, voxel grid, fixed-size subset.

Everything here is in metres; :func:`robust_radius` gives the scale that maps a scan to network units (the
network and the CEM's epsilon live on the ModelNet unit sphere).
"""
from __future__ import annotations

import numpy as np

from cemnet_ros.core.jit import kernel
from cemnet_ros.pipeline.config import SAMPLING_METHODS

GOLDEN = np.uint64(0x9E3779B97F4A7C15)  # Fibonacci hashing: multiply, keep the top bits


def _xyz_array(points: np.ndarray) -> np.ndarray:
    """``points`` as an (n, 3) float32 or float64 array (other dtypes converted to float64); ValueError otherwise."""
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), not {pts.shape}")
    return pts if pts.dtype in (np.float32, np.float64) else pts.astype(np.float64)


def finite_points(points: np.ndarray) -> np.ndarray:
    """(n, 3) float64 rows whose three coordinates are all finite."""
    return _finite_rows(_xyz_array(points))


def finite_in_range(points: np.ndarray, min_range: float = 0.0, max_range: float = 0.0) -> np.ndarray:
    """The finite rows (float64) whose distance to the sensor origin lies in [min_range, max_range], in one pass
    over the scan; 0 disables a bound."""
    if min_range <= 0.0 and max_range <= 0.0:
        return finite_points(points)
    return _finite_rows_in_range(_xyz_array(points), *_range_bounds(min_range, max_range))


def voxel_downsample(points: np.ndarray, voxel_size: float) -> np.ndarray:
    """One point per occupied voxel: the centroid of the points inside it (voxel_size <= 0 = unchanged).

    Voxels in order of their first point (a scan's order keeps neighbouring voxels close in memory).
    """
    if voxel_size <= 0.0 or len(points) == 0:
        return points
    return _voxel_centroids(np.ascontiguousarray(points, dtype=np.float64), float(voxel_size), 0.0, np.inf)[0]


def voxel_downsample_in_range(points: np.ndarray, voxel_size: float, min_range: float = 0.0,
                              max_range: float = 0.0) -> tuple[np.ndarray, int]:
    """(:func:`voxel_downsample` of :func:`finite_in_range`, the number of points in range) in two passes over the
    scan and no copy of it: the same centroids, bit for bit. voxel_size <= 0: the points in range themselves."""
    if voxel_size <= 0.0:
        kept = finite_in_range(points, min_range, max_range)
        return kept, len(kept)
    return _voxel_centroids(_xyz_array(points), float(voxel_size), *_range_bounds(min_range, max_range))


def _range_bounds(min_range: float, max_range: float) -> tuple[float, float]:
    """The kernels' [low, high] range bounds of a crop whose 0 disables a bound."""
    return float(min_range) if min_range > 0.0 else 0.0, float(max_range) if max_range > 0.0 else np.inf


@kernel
def _finite_rows(points):
    """The rows of ``points`` whose coordinates are all finite, as float64 (two passes: count, copy)."""
    n = 0
    for i in range(points.shape[0]):
        if np.isfinite(points[i, 0]) and np.isfinite(points[i, 1]) and np.isfinite(points[i, 2]):
            n += 1
    out = np.empty((n, 3))
    k = 0
    for i in range(points.shape[0]):
        if np.isfinite(points[i, 0]) and np.isfinite(points[i, 1]) and np.isfinite(points[i, 2]):
            out[k, 0], out[k, 1], out[k, 2] = points[i, 0], points[i, 1], points[i, 2]
            k += 1
    return out


@kernel
def _finite_rows_in_range(points, min_range, max_range):
    """The rows of ``points`` with finite coordinates whose norm (in float64) lies in [min_range, max_range]."""
    keep = np.empty(points.shape[0], dtype=np.bool_)
    n = 0
    for i in range(points.shape[0]):
        x, y, z = np.float64(points[i, 0]), np.float64(points[i, 1]), np.float64(points[i, 2])
        finite = np.isfinite(x) and np.isfinite(y) and np.isfinite(z)
        keep[i] = finite and min_range <= np.sqrt(x * x + y * y + z * z) <= max_range
        n += keep[i]
    out = np.empty((n, 3))
    k = 0
    for i in range(points.shape[0]):
        if keep[i]:
            out[k, 0], out[k, 1], out[k, 2] = points[i, 0], points[i, 1], points[i, 2]
            k += 1
    return out


@kernel
def _hash_slot(table, key, shift):
    """The row of ``table`` (key, value) holding ``key``, or the free row where it belongs (linear probing)."""
    mask = table.shape[0] - 1
    j = np.int64((np.uint64(key) * GOLDEN) >> shift)
    while table[j, 0] != key and table[j, 0] != -1:
        j = (j + 1) & mask
    return j


@kernel
def _doubled(table, bits):
    """``table`` rehashed into twice as many rows (2^(bits + 1))."""
    bigger = np.full((2 * table.shape[0], 2), -1, dtype=np.int64)
    shift = np.uint64(64 - bits - 1)
    for i in range(table.shape[0]):
        if table[i, 0] != -1:
            j = _hash_slot(bigger, table[i, 0], shift)
            bigger[j, 0], bigger[j, 1] = table[i, 0], table[i, 1]
    return bigger


RECENT = 4096  # voxels remembered by key outside the hash table (a power of two): a scan revisits them


@kernel
def _voxel_centroids(points, voxel_size, min_range, max_range):
    """(centroid per voxel floor(p / voxel_size), points counted) over the rows of ``points`` with finite
    coordinates whose norm lies in [min_range, max_range], in one pass through a hash table of int64 voxel keys.

    A first pass marks the kept rows and finds their extremes (floor(x / voxel_size) is monotone in x). Keys
    count cells from the lowest occupied one (a mixed-radix number), so no coordinate range is too large. The
    table starts small (scans have several points per voxel) and doubles when half full; a scan revisits the
    voxels it has just filled, so a small table of recent voxels by key is tried first. One long kernel: numba
    compiles no closures, and split into calls the hot loop would pass the table back and forth.
    """
    low, high = np.full(3, np.inf), np.full(3, -np.inf)
    keep = np.empty(points.shape[0], dtype=np.bool_)
    n = 0
    for i in range(points.shape[0]):
        x, y, z = np.float64(points[i, 0]), np.float64(points[i, 1]), np.float64(points[i, 2])
        keep[i] = np.isfinite(x) and np.isfinite(y) and np.isfinite(z) and \
            min_range <= np.sqrt(x * x + y * y + z * z) <= max_range
        if keep[i]:
            n += 1
            low[0], low[1], low[2] = min(low[0], x), min(low[1], y), min(low[2], z)
            high[0], high[1], high[2] = max(high[0], x), max(high[1], y), max(high[2], z)
    if n == 0:
        return np.empty((0, 3)), 0
    lo, hi = np.floor(low / voxel_size).astype(np.int64), np.floor(high / voxel_size).astype(np.int64)
    dim_y, dim_z = hi[1] - lo[1] + 1, hi[2] - lo[2] + 1
    bits = 10
    while (1 << bits) < n // 2:
        bits += 1
    table = np.full((1 << bits, 2), -1, dtype=np.int64)  # (key, voxel) rows
    sums = np.empty((n, 3))
    counts = np.empty(n, dtype=np.int64)
    n_voxels = 0
    recent = np.full((RECENT, 2), -1, dtype=np.int64)  # (key, voxel) of recently seen voxels, by key % RECENT
    for i in range(points.shape[0]):
        if not keep[i]:
            continue
        x, y, z = np.float64(points[i, 0]), np.float64(points[i, 1]), np.float64(points[i, 2])
        key = ((np.int64(np.floor(x / voxel_size)) - lo[0]) * dim_y
               + np.int64(np.floor(y / voxel_size)) - lo[1]) * dim_z + np.int64(np.floor(z / voxel_size)) - lo[2]
        r = key & (RECENT - 1)
        if recent[r, 0] == key:
            v = recent[r, 1]
        else:
            j = _hash_slot(table, key, np.uint64(64 - bits))
            if table[j, 0] == -1:
                table[j, 0], table[j, 1] = key, n_voxels
                sums[n_voxels, 0] = sums[n_voxels, 1] = sums[n_voxels, 2] = 0.0
                counts[n_voxels] = 0
                n_voxels += 1
            v = table[j, 1]
            recent[r, 0], recent[r, 1] = key, v
            if 2 * n_voxels > table.shape[0]:
                table = _doubled(table, bits)
                bits += 1
        sums[v, 0] += x
        sums[v, 1] += y
        sums[v, 2] += z
        counts[v] += 1
    out = np.empty((n_voxels, 3))
    for v in range(n_voxels):
        for k in range(3):
            out[v, k] = sums[v, k] / counts[v]
    return out, n


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


def compile_kernels() -> None:
    """Compile the preprocessing kernels now, so that the first scan is not slow.

    For the clouds the pipeline sees: float64 (a decoded PointCloud2) and the float32 x, y, z columns of a KITTI
    x, y, z, intensity array; other dtypes and layouts compile on first use.
    """
    with_intensity = np.random.default_rng(0).random((16, 4)).astype(np.float32)
    finite_points(with_intensity[:, :3])
    finite_in_range(with_intensity[:, :3], 0.1, 1.0)
    voxel_downsample(finite_in_range(with_intensity[:, :3].astype(np.float64), 0.1, 1.0), 0.5)
    voxel_downsample_in_range(with_intensity[:, :3], 0.5, 0.1, 1.0)
    voxel_downsample_in_range(with_intensity[:, :3].astype(np.float64), 0.5, 0.1, 1.0)
