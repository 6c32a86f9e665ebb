"""A scan as small_gicp aligns it: thinned to a voxel, with each point's covariance and a KD-tree (metres).

The map keeps its last scan so (:attr:`~.voxel_map.VoxelMap.last_scan`), the target of the polish's basin stage
(:mod:`cemnet_ros.pipeline.steps.basin`). The thinning and the alignment run single-threaded on purpose: small_gicp
splits their parallel sums dynamically, so their rounding, and with it the trajectory, would change with the
machine's load. Each point's covariance depends on its neighbours only, so those are estimated in parallel, on
at most the threads numba may use in the calling thread (:mod:`cemnet_ros.pipeline.threads`).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numba
import numpy as np
import small_gicp

THREADS = 1  # deterministic sums (see above)
COVARIANCE_THREADS = 2  # at most; per point: the same result on any number of threads
NEIGHBOURS = 10  # points of each local distribution (small_gicp's default)
GICP_VOXELS = 2.0  # map voxels: the clouds GICP aligns are this coarse (it finds a basin; the fine polish refines)


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
    cloud = small_gicp.voxelgrid_sampling(np.ascontiguousarray(points, dtype=np.float64), float(voxel),
                                          num_threads=THREADS)
    threads = min(COVARIANCE_THREADS, numba.get_num_threads())
    tree = small_gicp.KdTree(cloud, num_threads=threads)
    small_gicp.estimate_covariances(cloud, tree, num_neighbors=NEIGHBOURS, num_threads=threads)
    return GicpCloud(cloud, tree)
