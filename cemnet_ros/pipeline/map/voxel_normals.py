"""Normals of the local map's points (numba): PCA of the map points around each new point, voxel by voxel.

Every point gets a unit normal and a planarity weight in [0, 1] once, when it is inserted, for the
point-to-plane ICP of :mod:`cemnet_ros.pipeline.steps.refine`. The storage layout is :mod:`.voxel_hash`'s.
"""
from __future__ import annotations

import numba
import numpy as np

from cemnet_ros.core.jit import FASTMATH_INF_SAFE, kernel
from cemnet_ros.pipeline.map.voxel_hash import find, pack, unpack

MIN_NEIGHBOURS = 5  # fewer map points around a new point leave its normal undefined (planarity 0)
NORMAL_RADIUS = 1.0  # neighbourhood of the normal estimation, in voxels


@kernel  # no fastmath of its own: compiled with its caller's, _voxel_normals' (see cemnet_ros.core.jit)
def _smallest_eigen(a00, a01, a02, a11, a12, a22):
    """(normal, planarity) of a 3x3 covariance: the smallest principal axis and (s_mid - s_min) / s_max.

    s are the principal standard deviations. That planarity is near 1 for a patch of a surface and near 0 for a
    line of points (one LiDAR ring, its range noise across it), whose smallest axis is an arbitrary direction
    across the line: such a normal would bias the point-to-plane fit.

    Closed form: the eigenvalues by the trigonometric solution, the eigenvector as the largest cross product of
    two rows of (A - lambda_min I).
    """
    q = (a00 + a11 + a22) / 3.0
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    p = np.sqrt(((a00 - q) ** 2 + (a11 - q) ** 2 + (a22 - q) ** 2 + 2.0 * p1) / 6.0)
    if p < 1e-150:
        return 0.0, 0.0, 1.0, 0.0  # isotropic (or a single point): no plane
    b00, b11, b22 = (a00 - q) / p, (a11 - q) / p, (a22 - q) / p
    b01, b02, b12 = a01 / p, a02 / p, a12 / p
    det = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02)
    phi = np.arccos(min(max(det / 2.0, -1.0), 1.0)) / 3.0
    lam_max = q + 2.0 * p * np.cos(phi)
    lam_min = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
    lam_mid = 3.0 * q - lam_max - lam_min
    s_min, s_mid, s_max = np.sqrt(max(lam_min, 0.0)), np.sqrt(max(lam_mid, 0.0)), np.sqrt(max(lam_max, 0.0))
    planarity = min(max((s_mid - s_min) / s_max, 0.0), 1.0) if s_max > 0.0 else 0.0
    c00, c11, c22 = a00 - lam_min, a11 - lam_min, a22 - lam_min
    x0, x1, x2 = a01 * a12 - a02 * c11, a02 * a01 - c00 * a12, c00 * c11 - a01 * a01
    y0, y1, y2 = a01 * c22 - a02 * a12, a02 * a02 - c00 * c22, c00 * a12 - a01 * a02
    z0, z1, z2 = c11 * c22 - a12 * a12, a12 * a02 - a01 * c22, a01 * a12 - c11 * a02
    nx, ny, nz = x0 * x0 + x1 * x1 + x2 * x2, y0 * y0 + y1 * y1 + y2 * y2, z0 * z0 + z1 * z1 + z2 * z2
    if nx >= ny and nx >= nz and nx > 0.0:
        s = 1.0 / np.sqrt(nx)
        return x0 * s, x1 * s, x2 * s, planarity
    if ny >= nz and ny > 0.0:
        s = 1.0 / np.sqrt(ny)
        return y0 * s, y1 * s, y2 * s, planarity
    if nz > 0.0:
        s = 1.0 / np.sqrt(nz)
        return z0 * s, z1 * s, z2 * s, planarity
    return 0.0, 0.0, 1.0, 0.0


@kernel
def _neighbour_voxels(v, rings, voxel_keys, table, shift, out):
    """The occupied voxels within ``rings`` of voxel ``v`` (itself included) into ``out``; returns how many."""
    ix, iy, iz = unpack(voxel_keys[v])
    k = 0
    for a in range(ix - rings, ix + rings + 1):
        for b in range(iy - rings, iy + rings + 1):
            for c in range(iz - rings, iz + rings + 1):
                u = find(pack(a, b, c), table, shift)
                if u >= 0:
                    out[k] = u
                    k += 1
    return k


@kernel(fastmath=FASTMATH_INF_SAFE)
def _voxel_normals(v, n_new, voxel_size, m, pts, counts, normals, planarity, voxel_keys, table, shift, around):
    """Normal and planarity of the last ``n_new`` points of voxel ``v``: PCA of the map points around each.

    The neighbouring voxels are looked up once, for all the voxel's new points; ``around`` is scratch space.
    """
    radius = NORMAL_RADIUS * voxel_size
    r_sq = radius * radius
    n_around = _neighbour_voxels(v, int(np.ceil(NORMAL_RADIUS)), voxel_keys, table, shift, around)
    for slot in range(v * m + counts[v] - n_new, v * m + counts[v]):
        px, py, pz = pts[slot, 0], pts[slot, 1], pts[slot, 2]
        n = sx = sy = sz = sxx = sxy = sxz = syy = syz = szz = 0.0
        for a in range(n_around):
            u = around[a]
            for j in range(u * m, u * m + counts[u]):
                dx, dy, dz = pts[j, 0] - px, pts[j, 1] - py, pts[j, 2] - pz  # small: no cancellation
                w = 1.0 if dx * dx + dy * dy + dz * dz <= r_sq else 0.0  # a select, not a branch
                n += w
                sx += w * dx
                sy += w * dy
                sz += w * dz
                sxx += w * dx * dx
                sxy += w * dx * dy
                sxz += w * dx * dz
                syy += w * dy * dy
                syz += w * dy * dz
                szz += w * dz * dz
        if n < MIN_NEIGHBOURS:
            normals[slot, 0], normals[slot, 1], normals[slot, 2], planarity[slot] = 0.0, 0.0, 1.0, 0.0
            continue
        mx, my, mz = sx / n, sy / n, sz / n
        normals[slot, 0], normals[slot, 1], normals[slot, 2], planarity[slot] = _smallest_eigen(
            sxx / n - mx * mx, sxy / n - mx * my, sxz / n - mx * mz, syy / n - my * my, syz / n - my * mz,
            szz / n - mz * mz)


@kernel(parallel=True)
def estimate_normals(voxels, n_new, voxel_size, m, pts, counts, normals, planarity, voxel_keys, table, shift,
                     around):
    """:func:`_voxel_normals` of each voxel ``voxels[i]`` (``n_new[i]`` new points) in parallel.

    ``around`` (threads, (2 rings + 1)^3) is per-thread scratch space.
    """
    for i in numba.prange(voxels.shape[0]):
        _voxel_normals(voxels[i], n_new[i], voxel_size, m, pts, counts, normals, planarity, voxel_keys, table,
                       shift, around[numba.get_thread_id()])
