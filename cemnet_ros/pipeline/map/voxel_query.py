"""Queries of the local map (numba): exact nearest map point within a bound, map points within a ball.

:func:`nearest_slot` is also the correspondence search of the point-to-plane ICP
(:mod:`cemnet_ros.pipeline.steps.refine`), on a map's :meth:`~cemnet_ros.pipeline.map.voxel_map.VoxelMap.view`.
"""
from __future__ import annotations

import numba
import numpy as np

from cemnet_ros.core.jit import FASTMATH_INF_SAFE, kernel
from cemnet_ros.pipeline.map.voxel_hash import cell_index, find, pack, unpack


@kernel(fastmath=FASTMATH_INF_SAFE)
def _scan_voxel(v, qx, qy, qz, pts, counts, m, best_sq, best):
    """Closest of voxel ``v``'s points if nearer than ``best_sq``: (best_sq, best slot)."""
    for j in range(v * m, v * m + counts[v]):
        dx, dy, dz = pts[j, 0] - qx, pts[j, 1] - qy, pts[j, 2] - qz
        d = dx * dx + dy * dy + dz * dz
        if d < best_sq:
            best_sq, best = d, j
    return best_sq, best


@kernel(fastmath=FASTMATH_INF_SAFE)
def _axis_order(q, max_distance, voxel_size):
    """A query's cells along one axis, nearest first: (own cell, step towards its nearer face, cells to visit).

    The j-th cell is own + side * (j + 1) // 2 for odd j, own - side * j // 2 for even j; its distance from the
    query never decreases with j, so a search along the axis can stop at the first cell that is too far.
    """
    own = cell_index(q, voxel_size)
    side = 1 if q - own * voxel_size > 0.5 * voxel_size else -1
    reach = max(own - cell_index(q - max_distance, voxel_size), cell_index(q + max_distance, voxel_size) - own)
    return own, side, 2 * reach + 1


@kernel(fastmath=FASTMATH_INF_SAFE)
def _axis_cell(own, side, j):
    """The j-th cell of :func:`_axis_order`."""
    return own + side * ((j + 1) // 2) if j % 2 == 1 else own - side * (j // 2)


@kernel(fastmath=FASTMATH_INF_SAFE)
def _gap(q, cell, own, voxel_size):
    """Distance along one axis from coordinate ``q`` (in voxel ``own``) to voxel ``cell``."""
    if cell < own:
        return q - (cell + 1) * voxel_size
    if cell > own:
        return cell * voxel_size - q
    return 0.0


@kernel(fastmath=FASTMATH_INF_SAFE)
def nearest_slot(qx, qy, qz, max_distance, view):
    """(squared distance, slot) of the nearest map point within ``max_distance``; (max_distance^2, -1) if none.

    Exact for any ``max_distance``: every voxel that the ball reaches is visited, nearest cells first along each
    axis, until its box is farther than the best point found so far.
    """
    pts, counts, table, shift, voxel_size, m = view
    best_sq, best = max_distance * max_distance, -1
    ox, sx, nx = _axis_order(qx, max_distance, voxel_size)
    oy, sy, ny = _axis_order(qy, max_distance, voxel_size)
    oz, sz, nz = _axis_order(qz, max_distance, voxel_size)
    for i in range(nx):
        a = _axis_cell(ox, sx, i)
        gx = _gap(qx, a, ox, voxel_size)
        if gx * gx >= best_sq:
            break
        for j in range(ny):
            b = _axis_cell(oy, sy, j)
            gy = _gap(qy, b, oy, voxel_size)
            gxy_sq = gx * gx + gy * gy
            if gxy_sq >= best_sq:
                break
            for k in range(nz):
                c = _axis_cell(oz, sz, k)
                gz = _gap(qz, c, oz, voxel_size)
                if gxy_sq + gz * gz >= best_sq:
                    break
                v = find(pack(a, b, c), table, shift)
                if v >= 0:
                    best_sq, best = _scan_voxel(v, qx, qy, qz, pts, counts, m, best_sq, best)
    return best_sq, best


@kernel(parallel=True)
def nearest_batch(query, max_distance, view, dist, slots):
    """Distance (inf if none) and slot (-1) of each query's nearest map point within ``max_distance``."""
    for i in numba.prange(query.shape[0]):
        d_sq, s = nearest_slot(query[i, 0], query[i, 1], query[i, 2], max_distance, view)
        slots[i] = s
        dist[i] = np.sqrt(d_sq) if s >= 0 else np.inf


@kernel
def slots_within(centre, radius, n_voxels, view, voxel_keys):
    """Slots of the map points within ``radius`` of ``centre``, voxel by voxel (the order of ``points``)."""
    pts, counts, _, _, voxel_size, m = view
    r_sq = radius * radius
    out = np.empty(n_voxels * m, dtype=np.int64)
    k = 0
    for v in range(n_voxels):
        gap_sq = 0.0  # from the centre to the voxel's box
        for axis, cell in enumerate(unpack(voxel_keys[v])):
            gap = max(cell * voxel_size - centre[axis], centre[axis] - (cell + 1) * voxel_size, 0.0)
            gap_sq += gap * gap
        if gap_sq > r_sq:
            continue
        for j in range(v * m, v * m + counts[v]):
            dx, dy, dz = pts[j, 0] - centre[0], pts[j, 1] - centre[1], pts[j, 2] - centre[2]
            if dx * dx + dy * dy + dz * dz <= r_sq:
                out[k] = j
                k += 1
    return out[:k]
