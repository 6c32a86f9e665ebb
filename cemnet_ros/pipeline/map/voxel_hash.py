"""The local map's storage kernels (numba): the voxel hash table, insertion into voxels, pruning of far voxels.

Storage is flat: voxel ``v`` owns the point slots ``v * M .. v * M + M - 1`` (``M = max_points_per_voxel``),
voxels are kept dense (a removed voxel is replaced by the last one) and an open-addressing hash table (linear
probing, backward-shift deletion) maps packed int64 voxel keys to voxel indices. Voxel indices are limited to
+-2^20 per axis (+-105 km at 0.1 m voxels). The map itself: :class:`cemnet_ros.pipeline.map.voxel_map.VoxelMap`.
"""
from __future__ import annotations

import numpy as np

from cemnet_ros.core.jit import kernel

EMPTY = -1  # a free hash table entry; packed keys are never negative
KEY_OFFSET = 1 << 20  # voxel indices are stored as 21-bit unsigned fields
KEY_MASK = (1 << 21) - 1
GOLDEN = np.uint64(0x9E3779B97F4A7C15)  # Fibonacci hashing: multiply, keep the top bits


# -- hash table -------------------------------------------------------------------------------------------------
@kernel
def cell_index(x, voxel_size):
    """Voxel index of a coordinate (the same floor as :func:`cemnet_ros.pipeline.steps.preprocess.voxel_downsample`)."""
    return np.int64(np.floor(x / voxel_size))


@kernel
def pack(ix, iy, iz):
    """One non-negative int64 per voxel: three 21-bit fields."""
    x, y, z = (ix + KEY_OFFSET) & KEY_MASK, (iy + KEY_OFFSET) & KEY_MASK, (iz + KEY_OFFSET) & KEY_MASK
    return (x << 42) | (y << 21) | z


@kernel
def unpack(key):
    """The voxel indices (ix, iy, iz) of a packed key."""
    return ((key >> 42) & KEY_MASK) - KEY_OFFSET, ((key >> 21) & KEY_MASK) - KEY_OFFSET, (key & KEY_MASK) - KEY_OFFSET


@kernel
def _probe_start(key, shift):
    """The table entry where ``key``'s probe starts."""
    return np.int64((np.uint64(key) * GOLDEN) >> np.uint64(shift))


@kernel
def find(key, table, shift):
    """Voxel index of ``key``, -1 if absent."""
    mask = table.shape[0] - 1
    i = _probe_start(key, shift)
    while True:
        k = table[i, 0]
        if k == key:
            return table[i, 1]
        if k == EMPTY:
            return -1
        i = (i + 1) & mask


@kernel
def _find_or_add(key, table, shift, new_voxel):
    """Voxel index of ``key``; absent keys get ``new_voxel``. Returns (voxel, added)."""
    mask = table.shape[0] - 1
    i = _probe_start(key, shift)
    while True:
        k = table[i, 0]
        if k == key:
            return table[i, 1], False
        if k == EMPTY:
            table[i, 0] = key
            table[i, 1] = new_voxel
            return new_voxel, True
        i = (i + 1) & mask


@kernel
def _remove_key(key, table, shift):
    """Delete ``key`` (present) and shift the rest of its probe cluster back, so that no tombstone is needed."""
    mask = table.shape[0] - 1
    i = _probe_start(key, shift)
    while table[i, 0] != key:
        i = (i + 1) & mask
    j = i
    while True:
        j = (j + 1) & mask
        if table[j, 0] == EMPTY:
            break
        home = _probe_start(table[j, 0], shift)
        stays = (i < home <= j) if i <= j else (home > i or home <= j)  # home lies cyclically in (i, j]
        if not stays:
            table[i, 0], table[i, 1] = table[j, 0], table[j, 1]
            i = j
    table[i, 0] = EMPTY


@kernel
def rehash(voxel_keys, n_voxels, table, shift):
    """Fill an empty table with the keys of voxels 0 .. n_voxels - 1."""
    for v in range(n_voxels):
        _find_or_add(voxel_keys[v], table, shift, v)


# -- insertion and pruning ------------------------------------------------------------------------------------
@kernel
def insert_points(points, voxel_size, m, pts, counts, voxel_keys, n_voxels, table, shift, inserted):
    """Put each point into its voxel unless the voxel is full; returns (n_voxels, n_inserted).

    ``inserted`` receives the slots written; the caller has reserved room for one new voxel per point.
    """
    n_inserted = 0
    for i in range(points.shape[0]):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        key = pack(cell_index(x, voxel_size), cell_index(y, voxel_size), cell_index(z, voxel_size))
        v, added = _find_or_add(key, table, shift, n_voxels)
        if added:
            voxel_keys[v] = key
            counts[v] = 0
            n_voxels += 1
        c = counts[v]
        if c >= m:
            continue
        slot = v * m + c
        pts[slot, 0], pts[slot, 1], pts[slot, 2] = x, y, z
        counts[v] = c + 1
        inserted[n_inserted] = slot
        n_inserted += 1
    return n_voxels, n_inserted


@kernel
def prune_far_voxels(sensor, max_distance, voxel_size, m, pts, normals, planarity, counts, voxel_keys, n_voxels,
                     table, shift):
    """Remove the voxels whose centre is farther than ``max_distance`` from ``sensor``; returns n_voxels.

    A removed voxel is overwritten by the last one (already checked: the loop runs backwards).
    """
    max_sq = max_distance * max_distance
    for v in range(n_voxels - 1, -1, -1):
        key = voxel_keys[v]
        distance_sq = 0.0
        for axis, cell in enumerate(unpack(key)):
            distance_sq += ((cell + 0.5) * voxel_size - sensor[axis]) ** 2
        if distance_sq <= max_sq:
            continue
        _remove_key(key, table, shift)
        last = n_voxels - 1
        n_voxels = last
        if v == last:
            continue
        voxel_keys[v] = voxel_keys[last]
        counts[v] = counts[last]
        for k in range(counts[last]):
            for axis in range(3):
                pts[v * m + k, axis] = pts[last * m + k, axis]
                normals[v * m + k, axis] = normals[last * m + k, axis]
            planarity[v * m + k] = planarity[last * m + k]
        mask = table.shape[0] - 1
        i = _probe_start(voxel_keys[v], shift)
        while table[i, 0] != voxel_keys[v]:
            i = (i + 1) & mask
        table[i, 1] = v
    return n_voxels
