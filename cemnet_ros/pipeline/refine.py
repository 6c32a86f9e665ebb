"""Optional local refinement of a CEMNet result: point-to-plane ICP on the voxelised clouds, in metres.

CEMNet sees ``n_points`` (768) random points per cloud, which bounds its accuracy to a fraction of the point
spacing; a few point-to-plane ICP steps on the denser voxel clouds, started from the CEM's answer, remove
that sampling error (``refine_iters = 0`` turns it off and keeps the paper's method).
"""
from __future__ import annotations

import numba
import numpy as np
from scipy.spatial import cKDTree

MIN_PAIRS = 10


def estimate_normals(points: np.ndarray, tree: cKDTree, k: int = 10) -> np.ndarray:
    """Unit normals from the smallest principal axis of each point's k nearest neighbours."""
    k = min(k, len(points))
    _, idx = tree.query(points, k=k)
    return _smallest_axes(points, idx)


@numba.njit(cache=True, fastmath=True, parallel=True)
def _smallest_axes(points, idx):
    """Per point: the eigenvector of the smallest eigenvalue of its neighbourhood covariance (closed form)."""
    out = np.empty((idx.shape[0], 3))
    k = idx.shape[1]
    for i in numba.prange(idx.shape[0]):
        mx = my = mz = 0.0
        for j in idx[i]:
            mx += points[j, 0]
            my += points[j, 1]
            mz += points[j, 2]
        mx, my, mz = mx / k, my / k, mz / k
        a00 = a01 = a02 = a11 = a12 = a22 = 0.0
        for j in idx[i]:
            dx, dy, dz = points[j, 0] - mx, points[j, 1] - my, points[j, 2] - mz
            a00 += dx * dx
            a01 += dx * dy
            a02 += dx * dz
            a11 += dy * dy
            a12 += dy * dz
            a22 += dz * dz
        # Smallest eigenvalue of the symmetric 3x3 (trigonometric solution), then its eigenvector as the
        # largest cross product of two rows of (A - lambda I).
        q = (a00 + a11 + a22) / 3.0
        p1 = a01 * a01 + a02 * a02 + a12 * a12
        p = np.sqrt(((a00 - q) ** 2 + (a11 - q) ** 2 + (a22 - q) ** 2 + 2.0 * p1) / 6.0)
        out[i, 0], out[i, 1], out[i, 2] = 0.0, 0.0, 1.0
        if p < 1e-150:
            continue
        b00, b11, b22 = (a00 - q) / p, (a11 - q) / p, (a22 - q) / p
        b01, b02, b12 = a01 / p, a02 / p, a12 / p
        det = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02)
        r = min(max(det / 2.0, -1.0), 1.0)
        lam = q + 2.0 * p * np.cos(np.arccos(r) / 3.0 + 2.0 * np.pi / 3.0)
        c00, c11, c22 = a00 - lam, a11 - lam, a22 - lam
        # rows: (c00, a01, a02), (a01, c11, a12), (a02, a12, c22)
        x0, x1, x2 = a01 * a12 - a02 * c11, a02 * a01 - c00 * a12, c00 * c11 - a01 * a01
        y0, y1, y2 = a01 * c22 - a02 * a12, a02 * a02 - c00 * c22, c00 * a12 - a01 * a02
        z0, z1, z2 = c11 * c22 - a12 * a12, a12 * a02 - a01 * c22, a01 * a12 - c11 * a02
        nx, ny, nz = x0 * x0 + x1 * x1 + x2 * x2, y0 * y0 + y1 * y1 + y2 * y2, z0 * z0 + z1 * z1 + z2 * z2
        if nx >= ny and nx >= nz and nx > 0:
            s = 1.0 / np.sqrt(nx)
            out[i, 0], out[i, 1], out[i, 2] = x0 * s, x1 * s, x2 * s
        elif ny >= nz and ny > 0:
            s = 1.0 / np.sqrt(ny)
            out[i, 0], out[i, 1], out[i, 2] = y0 * s, y1 * s, y2 * s
        elif nz > 0:
            s = 1.0 / np.sqrt(nz)
            out[i, 0], out[i, 1], out[i, 2] = z0 * s, z1 * s, z2 * s
    return out


class PlaneTarget:
    """A target cloud with its k-d tree and normals, built once and reused while it is the reference."""

    def __init__(self, points: np.ndarray) -> None:
        self.points = np.asarray(points, dtype=np.float64)
        self.tree = cKDTree(self.points)
        self.normals = estimate_normals(self.points, self.tree)


def point_to_plane_icp(source: np.ndarray, target: PlaneTarget, initial: np.ndarray, start_distance: float,
                       end_distance: float, iters: int) -> np.ndarray:
    """Refine ``initial`` (4x4, source -> target) by ``iters`` Gauss-Newton point-to-plane steps.

    The pairing distance shrinks geometrically from ``start_distance`` (catch the CEM's residual error) to
    ``end_distance`` (no biased far pairs at the end); with fewer than MIN_PAIRS pairs the estimate stays.
    """
    tree, normals = target.tree, target.normals
    transform = np.array(initial, dtype=np.float64)
    for max_distance in np.geomspace(start_distance, min(end_distance, start_distance), iters):
        moved = source @ transform[:3, :3].T + transform[:3, 3]
        dist, idx = tree.query(moved, distance_upper_bound=max_distance, workers=-1)
        ok = np.isfinite(dist)
        if ok.sum() < MIN_PAIRS:
            break
        p, q, n = moved[ok], target.points[idx[ok]], normals[idx[ok]]
        residual = np.einsum("ij,ij->i", p - q, n)
        jacobian = np.hstack([np.cross(p, n), n])  # d(residual)/d(rotation vector, translation)
        delta = np.linalg.solve(jacobian.T @ jacobian + 1e-9 * np.eye(6), -jacobian.T @ residual)
        angle = np.linalg.norm(delta[:3])
        step = np.eye(4)
        if angle > 0:
            axis = delta[:3] / angle
            skew = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
            step[:3, :3] = np.eye(3) + np.sin(angle) * skew + (1 - np.cos(angle)) * skew @ skew
        step[:3, 3] = delta[3:]
        transform = step @ transform
    return transform
