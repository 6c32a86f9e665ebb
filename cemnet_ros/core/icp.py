"""Point-to-point ICP of one motion on numpy clouds: exact k-d tree correspondences, Kabsch (SVD) updates.

The package's one such ICP: the optional final refinement of a registration (``CEMConfig.refine_icp_steps``)
and the classical baseline of the evaluation (:func:`cemnet_ros.eval.baselines.icp`). The CEM's own ICP steps
(``CEMConfig.icp_steps``, behind the future reward) run in numba on look-up lattices (:mod:`.lattice_rewards`),
or batched in torch on CUDA (:mod:`.icp_torch`); the scan pipeline's polish is a point-to-plane ICP against its
map (:mod:`cemnet_ros.pipeline.steps.refine`).
"""
from __future__ import annotations

from typing import Optional

import numpy as np
from scipy.spatial import cKDTree

from .geometry import procrustes_np


def point_to_point_icp(source: np.ndarray, target: np.ndarray, rotation: np.ndarray, translation: np.ndarray,
                       max_iterations: int, max_distance: Optional[float] = None, tolerance: Optional[float] = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Refine ``target ~= rotation @ source + translation`` for (n, 3) and (m, 3) clouds by at most ``max_iterations``.

    Each step pairs every moved source point with its nearest target point, drops the pairs farther than
    ``max_distance`` (None: keeps all) and composes their Kabsch fit onto the motion; fewer than 3 pairs stop it.
    ``tolerance``: stop as well once the mean pair distance improves by less (None: run every iteration).
    """
    source, target = np.asarray(source, dtype=np.float64), np.asarray(target, dtype=np.float64)
    tree = cKDTree(target)
    previous = np.inf
    for _ in range(max_iterations):
        moved = source @ rotation.T + translation
        distances, index = tree.query(moved)
        keep = np.ones(len(moved), dtype=bool) if max_distance is None else distances <= max_distance
        if keep.sum() < 3:
            break
        step_r, step_t = procrustes_np(moved[keep], target[index[keep]])
        rotation, translation = step_r @ rotation, step_r @ translation + step_t
        if tolerance is not None:
            error = float(distances[keep].mean())
            if previous - error < tolerance:
                break
            previous = error
    return rotation, translation
