"""The wide stage of the polish: GICP (small_gicp) of a scan against the last scan its map took in, metres.

A start can be a metre or tens of degrees off (a fast turn, a recovery's hypothesis). GICP pairs each point's
local distribution with its neighbour's and finds the basin from much farther than a point-to-plane ICP on the
same points (docs/libraries.md has the figures); the point-to-plane polish against the whole map then brings the
precision and the Hessian (:mod:`.refine`). Both clouds are thinned to the map's voxel
(:mod:`~cemnet_ros.pipeline.map.gicp_cloud`); single-threaded, as they are made.
"""
from __future__ import annotations

import numpy as np
import small_gicp

from cemnet_ros.pipeline.map.gicp_cloud import THREADS, GicpCloud


def gicp(target: GicpCloud, source: GicpCloud, T_target_source: np.ndarray, max_distance: float,
         iters: int, settled: tuple[float, float] = (1e-3, np.radians(0.1))) -> np.ndarray:
    """GICP from ``T_target_source`` (4x4, source frame to the frame ``target`` is placed in) with pairs up to
    ``max_distance`` (m), at most ``iters`` steps, ending once a step moves less than ``settled`` (m, rad);
    the start itself if it found no answer."""
    T_start = np.linalg.inv(target.pose) @ np.asarray(T_target_source, dtype=np.float64) @ source.pose
    result = small_gicp.align(target.points, source.points, target.tree, init_T_target_source=T_start,
                              registration_type="GICP", max_correspondence_distance=float(max_distance),
                              num_threads=THREADS, max_iterations=int(iters), translation_epsilon=settled[0],
                              rotation_epsilon=settled[1])
    T_found = target.pose @ np.asarray(result.T_target_source, dtype=np.float64) @ np.linalg.inv(source.pose)
    return T_found if np.all(np.isfinite(T_found)) else np.asarray(T_target_source, dtype=np.float64).copy()
