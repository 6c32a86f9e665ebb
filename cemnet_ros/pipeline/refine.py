"""Optional local refinement of a CEMNet result: point-to-plane ICP on the voxelised clouds, in metres.

CEMNet sees ``n_points`` (768) random points per cloud, which bounds its accuracy to a fraction of the point
spacing; a few point-to-plane ICP steps on the denser voxel clouds, started from the CEM's answer, remove
that sampling error (``refine_iters = 0`` turns it off and keeps the paper's method).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

MIN_PAIRS = 10


def estimate_normals(points: np.ndarray, tree: cKDTree, k: int = 10) -> np.ndarray:
    """Unit normals from the smallest principal axis of each point's k nearest neighbours."""
    k = min(k, len(points))
    _, idx = tree.query(points, k=k)
    nbrs = points[idx] - points[idx].mean(axis=1, keepdims=True)
    _, vecs = np.linalg.eigh(np.einsum("nki,nkj->nij", nbrs, nbrs))
    return vecs[:, :, 0]


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
        dist, idx = tree.query(moved, distance_upper_bound=max_distance)
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
