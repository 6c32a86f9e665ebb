"""The look-up lattice: a cloud indexed for radius-bounded nearest-neighbour queries (CPU, numba).

The target cloud is the same for all N candidates of the CEM, so each cloud gets a lattice once per pair: nodes
``spacing`` apart (epsilon/4 by default), each holding its exact nearest cloud point within the radius.
A query then costs 8 look-ups and 8 distances, without branches: its answer is the nearest of the 8
surrounding nodes' points, which is the true nearest neighbour unless that point is nobody's node
neighbour (spacing well below the point spacing makes this rare: measured 99% exact on 768-point
ModelNet shapes, distance error below epsilon/10 otherwise). Only the neighbourhood within the radius
matters: the max-consensus reward is truncated at epsilon, and the ICP steps behind the "future"
reward ignore pairs farther than ``icp_radius`` (ICP with a maximum correspondence distance).

The rewards that query lattices are in :mod:`.lattice_rewards`; the numba policy in :mod:`.jit`.
"""
from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from .jit import kernel

MAX_NODES = 8_000_000  # a larger box gets a coarser lattice
FAR = 1e9  # coordinates of the sentinel point that empty nodes refer to


class Lattice(NamedTuple):
    """A cloud and the lattice over its box (numba takes it as one argument); nodes ``1 / inv_spacing`` apart."""

    cloud: np.ndarray  # (n, 3) float64, C-contiguous: the cloud itself, as the queries' side of a reward
    points: np.ndarray  # (n + 1, 3) float32 (distances need no more): the cloud, then a far sentinel
    node_nearest: np.ndarray  # (prod(dims),) int16 or int32: each node's nearest row of ``points`` (n: none)
    origin: np.ndarray  # (3,) float64
    dims: np.ndarray  # (3,) int64
    inv_spacing: float


def locality_order(points: np.ndarray, bits: int = 10) -> np.ndarray:
    """Permutation that puts ``points`` (n, 3) in Z-order (Morton order) over their bounding box.

    Queries made in this order touch neighbouring lattice nodes one after the other, so they hit the cache
    (faster rewards and ICP steps than in the clouds' own order: docs/evaluation.md, "Where the time goes").
    """
    lo, hi = points.min(0), points.max(0)
    cells = ((points - lo) / np.maximum(hi - lo, 1e-12) * ((1 << bits) - 1)).astype(np.int64)
    code = np.zeros(len(points), dtype=np.int64)
    for bit in range(bits):
        for axis in range(3):
            code |= ((cells[:, axis] >> bit) & 1) << (3 * bit + axis)
    return np.argsort(code, kind="stable")


def build_lattice(points: np.ndarray, radius: float, spacing: float) -> Lattice:
    """Index ``points`` (n, 3) for nearest-neighbour queries bounded by ``radius``."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    spacing = float(spacing)
    margin = radius + 2.0 * spacing
    lo, hi = points.min(0) - margin, points.max(0) + margin
    while np.prod(np.floor((hi - lo) / spacing) + 2) > MAX_NODES:
        spacing *= 1.25
    dims = (np.floor((hi - lo) / spacing) + 2).astype(np.int64)
    with_sentinel = np.vstack([points, np.full((1, 3), FAR)])
    index_type = np.int16 if len(points) < np.iinfo(np.int16).max else np.int32  # small lattices stay in cache
    node_nearest = np.full(int(np.prod(dims)), len(points), dtype=index_type)
    _splat(with_sentinel, lo, dims, spacing, radius + np.sqrt(3.0) * spacing, node_nearest)
    return Lattice(points, with_sentinel.astype(np.float32), node_nearest, lo, dims, 1.0 / spacing)


@kernel(fastmath=True, parallel=True)
def _splat(points, origin, dims, spacing, radius, node_nearest):
    """Exact nearest point (within ``radius``) of every lattice node; threads own slabs of constant x index.

    ``points`` ends with the far sentinel that every node starts at, so no distance array is needed.
    """
    r_sq = radius * radius
    n = points.shape[0] - 1
    lo = np.empty((n, 3), np.int64)
    hi = np.empty((n, 3), np.int64)
    for i in range(n):
        for k in range(3):
            lo[i, k] = max(int(np.ceil((points[i, k] - radius - origin[k]) / spacing)), 0)
            hi[i, k] = min(int(np.floor((points[i, k] + radius - origin[k]) / spacing)), dims[k] - 1)
    for a in numba.prange(dims[0]):
        x = origin[0] + a * spacing
        for i in range(n):
            if a < lo[i, 0] or a > hi[i, 0]:
                continue
            dx = x - points[i, 0]
            for b in range(lo[i, 1], hi[i, 1] + 1):
                y = origin[1] + b * spacing
                dy = y - points[i, 1]
                dxy = dx * dx + dy * dy
                if dxy > r_sq:
                    continue
                base = (a * dims[1] + b) * dims[2]
                for c in range(lo[i, 2], hi[i, 2] + 1):
                    z = origin[2] + c * spacing
                    dz = z - points[i, 2]
                    d = dxy + dz * dz
                    if d > r_sq:
                        continue
                    j = node_nearest[base + c]
                    ex, ey, ez = x - points[j, 0], y - points[j, 1], z - points[j, 2]
                    if d < ex * ex + ey * ey + ez * ez:
                        node_nearest[base + c] = i


@kernel(fastmath=True, inline="always")
def nearest_sq(lattice, qx, qy, qz):
    """Squared distance to the nearest of the 8 surrounding nodes' points, and its row (the sentinel if none).

    Unsigned indices spare numba's negative-index checks and float32 distances halve the gathered bytes
    (docs/evaluation.md, "Where the time goes").
    """
    points, node_nearest, origin, dims = lattice.points, lattice.node_nearest, lattice.origin, lattice.dims
    fx = (qx - origin[0]) * lattice.inv_spacing
    fy = (qy - origin[1]) * lattice.inv_spacing
    fz = (qz - origin[2]) * lattice.inv_spacing
    sentinel = np.uint64(points.shape[0] - 1)
    if fx < 0.0 or fy < 0.0 or fz < 0.0 or fx >= dims[0] - 1 or fy >= dims[1] - 1 or fz >= dims[2] - 1:
        return np.inf, sentinel  # outside the lattice, which reaches past every point by the radius
    ix, iy, iz = np.uint64(fx), np.uint64(fy), np.uint64(fz)
    ny, nz = np.uint64(dims[1]), np.uint64(dims[2])
    px, py, pz = np.float32(qx), np.float32(qy), np.float32(qz)
    best = np.float32(np.inf)
    best_i = sentinel
    for a in range(2):
        for b in range(2):
            base = ((ix + np.uint64(a)) * ny + iy + np.uint64(b)) * nz + iz
            for c in range(2):
                j = np.uint64(node_nearest[base + np.uint64(c)])
                dx = points[j, 0] - px
                dy = points[j, 1] - py
                dz = points[j, 2] - pz
                d = dx * dx + dy * dy + dz * dz
                closer = d < best
                best_i = j if closer else best_i  # selects, not branches: the winner is unpredictable
                best = min(d, best)
    return np.float64(best), best_i
