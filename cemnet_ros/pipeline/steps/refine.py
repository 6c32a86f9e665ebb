"""Point-to-plane ICP of a scan against the local map (:class:`~cemnet_ros.pipeline.map.voxel_map.VoxelMap`), metres.

Gauss-Newton on r_i = n_q . (R p_i + t - q), q the nearest map point within ``max_distance`` and n_q its
normal, each pair weighted by q's planarity times a Geman-McClure weight of its residual (a q without a
normal, planarity 0, gives no pair). The motion is updated as R <- exp([w]x) R, t <- t + v: a rotation about
the SOURCE origin (the sensor) in target axes, so the Jacobian row is [(R p_i) x n_q, n_q] and the returned
Hessian J^T W J (order [w, v]) is the information of exactly that parameterisation, which the covariance and
degeneracy analysis downstream rely on.

The per-point work (transform, nearest map point, residual, weighted J^T J and J^T r) is one numba kernel over
chunks of the source with per-chunk partial sums; only the 6x6 solve runs in numpy.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numba
import numpy as np

from cemnet_ros.core.jit import FASTMATH_INF_SAFE, kernel
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.map.voxel_map import compile_kernels as compile_map_kernels
from cemnet_ros.pipeline.map.voxel_query import nearest_slot

N_CHUNKS = 32  # partial sums; a fixed count: the sums do not depend on the thread count
N_SUMS = 30  # 21 upper-triangle entries of J^T W J, 6 of J^T W r, sum w r^2, sum w, pairs
UPPER = np.triu_indices(6)  # the kernel's order of the J^T W J entries
DAMPING = 1e-12  # relative to trace(H): keeps the solve defined along an exactly degenerate direction
COARSE_CONVERGENCE = 10.0  # the subset's steps end once one moves the points less than this x ``convergence``


@dataclass
class PolishResult:
    """The ICP's estimate and the information of its last correspondences."""

    T_target_source: np.ndarray  # (4, 4)
    hessian: np.ndarray  # (6, 6) J^T W J at the final estimate, order [rotation (rad), translation (m)]
    residual_variance: float  # weighted mean of squared point-to-plane residuals (m^2) at the end
    n_pairs: int  # pairs at the final estimate (those of the Hessian)
    iterations: int  # Gauss-Newton steps taken


@kernel(fastmath=FASTMATH_INF_SAFE)
def _chunk_sums(source, lo, hi, rot, trans, max_distance, kernel_scale, view, normals, planarity, out):
    """Add the pairs of source[lo:hi] moved by (rot, trans) to ``out`` (N_SUMS,).

    Layout: the 21 upper-triangle entries of J^T W J (row by row), the 6 of J^T W r, sum w r^2, sum w, pairs.
    """
    pts = view[0]
    k_sq = kernel_scale * kernel_scale
    jac = np.empty(6)
    for i in range(lo, hi):
        x, y, z = source[i, 0], source[i, 1], source[i, 2]
        rx = rot[0, 0] * x + rot[0, 1] * y + rot[0, 2] * z  # R p: the lever arm about the sensor
        ry = rot[1, 0] * x + rot[1, 1] * y + rot[1, 2] * z
        rz = rot[2, 0] * x + rot[2, 1] * y + rot[2, 2] * z
        qx, qy, qz = rx + trans[0], ry + trans[1], rz + trans[2]
        _, slot = nearest_slot(qx, qy, qz, max_distance, view)
        if slot < 0 or planarity[slot] <= 0.0:
            continue
        nx, ny, nz = normals[slot, 0], normals[slot, 1], normals[slot, 2]
        r = nx * (qx - pts[slot, 0]) + ny * (qy - pts[slot, 1]) + nz * (qz - pts[slot, 2])
        robust = k_sq / (k_sq + r * r)
        w = planarity[slot] * robust * robust  # Geman-McClure
        jac[0], jac[1], jac[2] = ry * nz - rz * ny, rz * nx - rx * nz, rx * ny - ry * nx  # (R p) x n
        jac[3], jac[4], jac[5] = nx, ny, nz
        k = 0
        for a in range(6):
            wa = w * jac[a]
            for b in range(a, 6):
                out[k] += wa * jac[b]
                k += 1
            out[21 + a] += wa * r
        out[27] += w * r * r
        out[28] += w
        out[29] += 1.0


@kernel(parallel=True)
def _normal_equations(source, rot, trans, max_distance, kernel_scale, view, normals, planarity, partial):
    """Per-chunk sums (rows of ``partial``, zeroed) over the pairs of ``source``, the chunks in parallel."""
    n, n_chunks = source.shape[0], partial.shape[0]
    for c in numba.prange(n_chunks):
        _chunk_sums(source, c * n // n_chunks, (c + 1) * n // n_chunks, rot, trans, max_distance, kernel_scale,
                    view, normals, planarity, partial[c])


def _linearise(target: VoxelMap, source: np.ndarray, rot: np.ndarray, trans: np.ndarray, max_distance: float,
               kernel_scale: float) -> tuple[np.ndarray, np.ndarray, float, int]:
    """(J^T W J (6, 6), J^T W r (6,), weighted residual variance, pairs) of ``source`` moved by (rot, trans)."""
    _, normals, planarity = target.slot_arrays()
    partial = np.zeros((N_CHUNKS, N_SUMS))
    _normal_equations(source, rot, trans, max_distance, kernel_scale, target.view(), normals, planarity, partial)
    sums = partial.sum(axis=0)
    hessian = np.empty((6, 6))
    hessian[UPPER] = sums[:21]
    hessian.T[UPPER] = sums[:21]
    variance = float(sums[27] / sums[28]) if sums[28] > 0.0 else 0.0
    return hessian, sums[21:27], variance, int(sums[29])


def _exp_so3(w: np.ndarray) -> np.ndarray:
    """Rotation matrix of the rotation vector ``w`` (Rodrigues)."""
    angle = float(np.linalg.norm(w))
    if angle < 1e-12:
        return np.eye(3)
    k = w / angle
    skew = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * skew + (1.0 - np.cos(angle)) * skew @ skew


def point_to_plane_icp(target: VoxelMap, source: np.ndarray, initial: np.ndarray, max_distance: float,
                       iters: int, *, kernel_scale: Optional[float] = None, min_pairs: int = 10,
                       convergence: float = 1e-4, coarse_stride: int = 1) -> PolishResult:
    """Refine ``initial`` (4x4, source -> target map) by at most ``iters`` Gauss-Newton point-to-plane steps.

    Stops early once a step moves the source less than ``convergence`` m (its translation plus its rotation
    times the source's RMS range); with fewer than ``min_pairs`` pairs the estimate stays. ``kernel_scale`` (m)
    of the Geman-McClure weights defaults to max_distance / 3.
    ``coarse_stride`` > 1: the steps run on every that-many-th point until one moves less than
    ``COARSE_CONVERGENCE`` x ``convergence``, then on all (the far steps need no more points than the direction
    takes; the last ones and the Hessian use them all). The Hessian, variance and pair count are those of the
    returned estimate on all points (one correspondence pass after the last step). A spatially coherent
    ``source`` order (a scan's own) runs ~20% faster than a random one: its consecutive queries share cache
    lines of the map.
    """
    source = np.ascontiguousarray(source, dtype=np.float64).reshape(-1, 3)
    max_distance = float(max_distance)
    kernel_scale = max_distance / 3.0 if kernel_scale is None else float(kernel_scale)
    initial = np.asarray(initial, dtype=np.float64)
    rot, trans = initial[:3, :3].copy(), initial[:3, 3].copy()
    coarse = coarse_stride > 1 and len(source) >= coarse_stride * max(min_pairs, 1)
    points = np.ascontiguousarray(source[::coarse_stride]) if coarse else source
    hessian, gradient, variance, n_pairs = _linearise(target, points, rot, trans, max_distance, kernel_scale)
    lever = float(np.sqrt(np.mean(np.einsum("ij,ij->i", source, source)))) if len(source) else 0.0
    done = 0
    while done < iters and n_pairs >= max(min_pairs, 1):
        delta = np.linalg.solve(hessian + DAMPING * np.trace(hessian) * np.eye(6), -gradient)
        rot = _exp_so3(delta[:3]) @ rot
        trans = trans + delta[3:]
        done += 1
        step = float(np.linalg.norm(delta[3:]) + lever * np.linalg.norm(delta[:3]))
        if coarse and (step < COARSE_CONVERGENCE * convergence or done == iters):
            coarse, points = False, source
        hessian, gradient, variance, n_pairs = _linearise(target, points, rot, trans, max_distance, kernel_scale)
        if step < convergence and not coarse:
            break
    if coarse:  # stopped for want of pairs on the subset: the result's information is that of all points
        hessian, gradient, variance, n_pairs = _linearise(target, source, rot, trans, max_distance, kernel_scale)
    T_target_source = np.eye(4)
    T_target_source[:3, :3], T_target_source[:3, 3] = rot, trans
    return PolishResult(T_target_source, hessian, variance, n_pairs, done)


def compile_kernels() -> None:
    """Compile the map's and the ICP's kernels on a tiny map now, so that the first scan is not the slow one."""
    compile_map_kernels()
    points = np.random.default_rng(0).random((64, 3))
    target = VoxelMap(0.5, max_points_per_voxel=4)
    target.update(points, np.zeros(3))
    point_to_plane_icp(target, points, np.eye(4), 0.3, 1)
