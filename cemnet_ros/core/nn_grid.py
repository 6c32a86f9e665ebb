"""CPU kernels (numba) for the CEM's inner loop: radius-bounded nearest neighbours through a lattice.

The target cloud is the same for all N candidates, so each cloud gets a lattice once per pair: nodes
``spacing`` apart (epsilon/4 by default), each holding its exact nearest cloud point within the radius.
A query then costs 8 look-ups and 8 distances, without branches: its answer is the nearest of the 8
surrounding nodes' points, which is the true nearest neighbour unless that point is nobody's node
neighbour (spacing well below the point spacing makes this rare: measured 99% exact on 768-point
ModelNet shapes, distance error below epsilon/10 otherwise). Only the neighbourhood within the radius
matters: the max-consensus reward is truncated at epsilon, and the ICP steps behind the "future"
reward ignore pairs farther than ``icp_radius`` (ICP with a maximum correspondence distance).

The kernels are compiled once per process (:func:`compile_kernels`, ~10 s), not cached on disk: the very same
machine code loaded from numba's cache ran 15-30% slower here than freshly compiled (measured: plain rewards
11 vs 15 ms, fused 43 vs 50 ms per 1000 candidates; the cached object file was byte-identical).
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

# OpenMP first: thread-safe when several threads register at once (a node's worker and a caller), and it
# skips the too-old TBB some machines carry (numba warns about it on every start otherwise).
numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]  # type: ignore[attr-defined]
MAX_NODES = 8_000_000  # a larger box gets a coarser lattice
FAR = 1e9  # coordinates of the sentinel point that empty nodes refer to


@dataclass
class Grid:
    """A lattice over a cloud's box; ``points`` ends with a far sentinel that empty nodes point to."""

    points: np.ndarray  # (n + 1, 3) float32 (distances need no more), the last row the sentinel
    node_nearest: np.ndarray  # (prod(dims),) int16 or int32
    origin: np.ndarray  # (3,) float64
    dims: np.ndarray  # (3,) int64
    spacing: float

    def astuple(self):
        """The kernels' view: (points, node_nearest, origin, dims, 1 / spacing)."""
        return self.points, self.node_nearest, self.origin, self.dims, 1.0 / self.spacing


def locality_order(points: np.ndarray, bits: int = 10) -> np.ndarray:
    """Permutation that puts ``points`` (n, 3) in Z-order (Morton order) over their bounding box.

    Queries made in this order touch neighbouring lattice nodes one after the other, so they hit the cache:
    measured ~18% faster rewards and ICP steps than the clouds' own order on ModelNet pairs.
    """
    lo, hi = points.min(0), points.max(0)
    cells = ((points - lo) / np.maximum(hi - lo, 1e-12) * ((1 << bits) - 1)).astype(np.int64)
    code = np.zeros(len(points), dtype=np.int64)
    for bit in range(bits):
        for axis in range(3):
            code |= ((cells[:, axis] >> bit) & 1) << (3 * bit + axis)
    return np.argsort(code, kind="stable")


def build_grid(points: np.ndarray, radius: float, spacing: float) -> Grid:
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
    return Grid(with_sentinel.astype(np.float32), node_nearest, lo, dims, spacing)


@numba.njit(fastmath=True, parallel=True)
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


@numba.njit(fastmath=True, inline="always")
def _nearest_sq(qx, qy, qz, points, node_nearest, origin, dims, inv_spacing):
    """Squared distance to the nearest of the 8 surrounding nodes' points, and its index (sentinel if none).

    Unsigned indices spare numba's negative-index checks and float32 distances halve the gathered bytes:
    together ~30% faster than signed float64 (measured on ModelNet pairs).
    """
    fx = (qx - origin[0]) * inv_spacing
    fy = (qy - origin[1]) * inv_spacing
    fz = (qz - origin[2]) * inv_spacing
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


@numba.njit(fastmath=True, inline="always")
def _moved(rot, trans, x, y, z):
    """R p + t for one point."""
    return (rot[0, 0] * x + rot[0, 1] * y + rot[0, 2] * z + trans[0],
            rot[1, 0] * x + rot[1, 1] * y + rot[1, 2] * z + trans[1],
            rot[2, 0] * x + rot[2, 1] * y + rot[2, 2] * z + trans[2])


@numba.njit(fastmath=True, inline="always")
def _inlier_score(sq, eps):
    """max(0, 1 - d / eps) for a squared distance."""
    return max(0.0, 1.0 - np.sqrt(sq) / eps)


@numba.njit(fastmath=True)
def _reverse_score(tgt, src_grid, rot, trans, eps):
    """sum_y max(0, 1 - d(y, R X + t)/eps): the source's lattice queried with R^T (y - t)."""
    pts, nodes, origin, dims, inv_spacing = src_grid
    acc = 0.0
    for i in range(tgt.shape[0]):
        x, y, z = tgt[i, 0] - trans[0], tgt[i, 1] - trans[1], tgt[i, 2] - trans[2]
        qx = rot[0, 0] * x + rot[1, 0] * y + rot[2, 0] * z
        qy = rot[0, 1] * x + rot[1, 1] * y + rot[2, 1] * z
        qz = rot[0, 2] * x + rot[1, 2] * y + rot[2, 2] * z
        d, _ = _nearest_sq(qx, qy, qz, pts, nodes, origin, dims, inv_spacing)
        acc += _inlier_score(d, eps)
    return acc


@numba.njit(fastmath=True)
def _consensus(src, tgt_grid, tgt, src_grid, rot, trans, eps):
    """Max-consensus reward mean_x max(0, 1 - d/eps) + mean_y max(0, 1 - d/eps) of one rigid motion."""
    pts, nodes, origin, dims, inv_spacing = tgt_grid
    acc = 0.0
    for i in range(src.shape[0]):
        qx, qy, qz = _moved(rot, trans, src[i, 0], src[i, 1], src[i, 2])
        d, _ = _nearest_sq(qx, qy, qz, pts, nodes, origin, dims, inv_spacing)
        acc += _inlier_score(d, eps)
    return acc / src.shape[0] + _reverse_score(tgt, src_grid, rot, trans, eps) / tgt.shape[0]


@numba.njit(fastmath=True)
def _icp_step(src, grid, radius_sq, rot, trans, eps):
    """One point-to-point ICP step (pairs within the radius) from (rot, trans).

    Returns the new motion, whether it moved (>= 3 pairs), and sum_x max(0, 1 - d/eps) of the starting motion:
    the same look-ups give the forward half of its max-consensus reward (the lattice holds every point within
    the ICP radius, which is larger than epsilon).
    """
    pts, nodes, origin, dims, inv_spacing = grid
    eps_sq = eps * eps
    # Scalar accumulators keep the hot loop in registers.
    n = 0
    score = 0.0
    sx0 = sx1 = sx2 = sy0 = sy1 = sy2 = 0.0
    s00 = s01 = s02 = s10 = s11 = s12 = s20 = s21 = s22 = 0.0
    for i in range(src.shape[0]):
        x0, x1, x2 = src[i, 0], src[i, 1], src[i, 2]
        qx, qy, qz = _moved(rot, trans, x0, x1, x2)
        d, j = _nearest_sq(qx, qy, qz, pts, nodes, origin, dims, inv_spacing)
        if d > radius_sq:
            continue
        if d <= eps_sq:
            score += _inlier_score(d, eps)
        y0, y1, y2 = pts[j, 0], pts[j, 1], pts[j, 2]
        n += 1
        sx0 += x0
        sx1 += x1
        sx2 += x2
        sy0 += y0
        sy1 += y1
        sy2 += y2
        s00 += x0 * y0
        s01 += x0 * y1
        s02 += x0 * y2
        s10 += x1 * y0
        s11 += x1 * y1
        s12 += x1 * y2
        s20 += x2 * y0
        s21 += x2 * y1
        s22 += x2 * y2
    if n < 3:
        return rot, trans, False, score
    mx = np.array([sx0, sx1, sx2]) / n
    my = np.array([sy0, sy1, sy2]) / n
    cov = np.array([[s00, s01, s02], [s10, s11, s12], [s20, s21, s22]]) / n - np.outer(mx, my)
    r = _best_rotation(cov)
    return r, my - r @ mx, True, score


@numba.njit(fastmath=True)
def _best_rotation(cov):
    """The proper rotation R maximising trace(R cov), cov = sum (x - mx)(y - my)^T: y ~ R x (Kabsch, det = +1).

    Horn's quaternion method: the unit quaternion of R is the top eigenvector of a symmetric 4x4 matrix, found
    by cyclic Jacobi rotations. Same result as the SVD with the reflection fix (tested to 1e-8), 4x faster
    than LAPACK's 3x3 SVD, which matters with 9,000 ICP steps per registration.
    """
    a = np.empty((4, 4))
    a[0, 0] = cov[0, 0] + cov[1, 1] + cov[2, 2]
    a[1, 1] = cov[0, 0] - cov[1, 1] - cov[2, 2]
    a[2, 2] = -cov[0, 0] + cov[1, 1] - cov[2, 2]
    a[3, 3] = -cov[0, 0] - cov[1, 1] + cov[2, 2]
    a[0, 1] = a[1, 0] = cov[1, 2] - cov[2, 1]
    a[0, 2] = a[2, 0] = cov[2, 0] - cov[0, 2]
    a[0, 3] = a[3, 0] = cov[0, 1] - cov[1, 0]
    a[1, 2] = a[2, 1] = cov[0, 1] + cov[1, 0]
    a[1, 3] = a[3, 1] = cov[2, 0] + cov[0, 2]
    a[2, 3] = a[3, 2] = cov[1, 2] + cov[2, 1]
    v = np.eye(4)
    total = (a * a).sum()
    for _ in range(16):
        off = a[0, 1] ** 2 + a[0, 2] ** 2 + a[0, 3] ** 2 + a[1, 2] ** 2 + a[1, 3] ** 2 + a[2, 3] ** 2
        if off <= 1e-24 * total:
            break
        for p in range(3):
            for q in range(p + 1, 4):
                if a[p, q] == 0.0:
                    continue
                theta = (a[q, q] - a[p, p]) / (2.0 * a[p, q])
                t = (1.0 if theta >= 0.0 else -1.0) / (abs(theta) + np.sqrt(theta * theta + 1.0))
                c = 1.0 / np.sqrt(t * t + 1.0)
                s = t * c
                for k in range(4):  # a <- J^T a J, v <- v J
                    a[k, p], a[k, q] = c * a[k, p] - s * a[k, q], s * a[k, p] + c * a[k, q]
                for k in range(4):
                    a[p, k], a[q, k] = c * a[p, k] - s * a[q, k], s * a[p, k] + c * a[q, k]
                for k in range(4):
                    v[k, p], v[k, q] = c * v[k, p] - s * v[k, q], s * v[k, p] + c * v[k, q]
    top = 0
    for i in range(1, 4):
        if a[i, i] > a[top, top]:
            top = i
    w, x, y, z = v[0, top], v[1, top], v[2, top], v[3, top]
    return np.array([[1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
                     [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
                     [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)]])


@numba.njit(fastmath=True)
def _fused(src, tgt, src_grid, icp_grid, rot, trans, eps, icp_radius, steps, alpha):
    """alpha * reward(rot, trans) + (1 - alpha) * reward after ``steps`` ICP steps from it.

    The first ICP step's look-ups double as the forward half of the current reward; a motion the ICP cannot
    move (fewer than 3 pairs) keeps its reward.
    """
    radius_sq = icp_radius * icp_radius
    r, t, moved, forward = _icp_step(src, icp_grid, radius_sq, rot, trans, eps)
    now = forward / src.shape[0] + _reverse_score(tgt, src_grid, rot, trans, eps) / tgt.shape[0]
    if not moved or steps == 0:
        return now
    for _ in range(steps - 1):
        r, t, moved, _ = _icp_step(src, icp_grid, radius_sq, r, t, eps)
        if not moved:
            break
    return alpha * now + (1.0 - alpha) * _consensus(src, icp_grid, tgt, src_grid, r, t, eps)


@numba.njit(parallel=True)
def consensus_batch(src, tgt, tgt_grid, src_grid, rots, transs, eps):
    """(C,) max-consensus rewards of C rigid motions of ``src`` against ``tgt``."""
    out = np.empty(rots.shape[0])
    for c in numba.prange(rots.shape[0]):
        out[c] = _consensus(src, tgt_grid, tgt, src_grid, rots[c], transs[c], eps)
    return out


@numba.njit(parallel=True)
def fused_batch(src, tgt, src_grid, icp_grid, rots, transs, eps, icp_radius, steps, alpha):
    """(C,) fused rewards alpha * now + (1 - alpha) * after ICP of C rigid motions (see :func:`_fused`)."""
    out = np.empty(rots.shape[0])
    for c in numba.prange(rots.shape[0]):
        out[c] = _fused(src, tgt, src_grid, icp_grid, rots[c], transs[c], eps, icp_radius, steps, alpha)
    return out


def compile_kernels() -> None:
    """Compile the kernels on a tiny cloud now, so that the first real registration is not the slow one."""
    points = np.random.default_rng(0).random((16, 3))
    grid = build_grid(points, 0.2, 0.05).astuple()
    rots, transs = np.ascontiguousarray(np.eye(3)[None]), np.zeros((1, 3))
    consensus_batch(points, points, grid, grid, rots, transs, 0.1)
    fused_batch(points, points, grid, grid, rots, transs, 0.1, 0.2, 1, 0.5)
