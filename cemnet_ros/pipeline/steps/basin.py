"""The wide stage of the polish: GICP (small_gicp) of a scan against the last scan its map took in, metres.

A start can be a metre or tens of degrees off (a fast turn, a recovery's hypothesis). GICP pairs each point's
local distribution with its neighbour's and finds the basin from much farther than a point-to-plane ICP on the
same points (docs/libraries.md has the figures); the point-to-plane polish against the whole map then brings the
precision and the Hessian (:mod:`.refine`). Both clouds are thinned to the map's voxel.

Single-threaded on purpose: small_gicp splits its parallel sums dynamically, so their rounding, and with it the
trajectory, would change with the machine's load.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import small_gicp

THREADS = 1  # deterministic sums (see above)
NEIGHBOURS = 10  # points of each local distribution (small_gicp's default)


@dataclass
class GicpCloud:
    """A cloud thinned to a voxel, with its points' covariances and its KD-tree (small_gicp's types), in its own
    frame, and ``pose``: that frame in the frame it is aligned in (a map's last scan: T_map_scan)."""

    points: small_gicp.PointCloud
    tree: small_gicp.KdTree
    pose: np.ndarray = field(default_factory=lambda: np.eye(4))

    def placed(self, pose: np.ndarray) -> "GicpCloud":
        """The same cloud at ``pose`` (no copy of the points: a scan kept by the map where it was inserted)."""
        return replace(self, pose=np.asarray(pose, dtype=np.float64).copy())


def gicp_cloud(points: np.ndarray, voxel: float) -> GicpCloud:
    """``points`` (n, 3) thinned to ``voxel`` (m), with covariances from their ``NEIGHBOURS`` nearest."""
    cloud, tree = small_gicp.preprocess_points(np.ascontiguousarray(points, dtype=np.float64), float(voxel),
                                               num_neighbors=NEIGHBOURS, num_threads=THREADS)
    return GicpCloud(cloud, tree)


def gicp(target: GicpCloud, source: GicpCloud, T_target_source: np.ndarray, max_distance: float,
         iters: int) -> np.ndarray:
    """GICP from ``T_target_source`` (4x4, source frame to the frame ``target`` is placed in) with pairs up to
    ``max_distance`` (m), at most ``iters`` steps (the start itself if it found no answer)."""
    T_start = np.linalg.inv(target.pose) @ np.asarray(T_target_source, dtype=np.float64) @ source.pose
    result = small_gicp.align(target.points, source.points, target.tree, init_T_target_source=T_start,
                              registration_type="GICP", max_correspondence_distance=float(max_distance),
                              num_threads=THREADS, max_iterations=int(iters))
    T_found = target.pose @ np.asarray(result.T_target_source, dtype=np.float64) @ np.linalg.inv(source.pose)
    return T_found if np.all(np.isfinite(T_found)) else np.asarray(T_target_source, dtype=np.float64).copy()
