"""Batched point-to-point ICP on torch tensors (brute-force correspondences; the CUDA/gradient path).

One motion on numpy clouds (exact k-d tree correspondences): :func:`.icp.point_to_point_icp`.
"""
from __future__ import annotations

import torch

from .geometry_torch import procrustes, transform_points
from .rewards import nearest_sq_distances


def batch_icp(source: torch.Tensor, target: torch.Tensor, rotation: torch.Tensor, translation: torch.Tensor,
              steps: int, max_distance: float | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Refine motions (C, 3, 3), (C, 3) of source (C or 1, n, 3) onto target (C or 1, m, 3) by ``steps`` ICP steps.

    Correspondences farther than ``max_distance`` are ignored; a motion with fewer than 3 left keeps its value.
    """
    for _ in range(steps):
        moved = transform_points(source, rotation, translation)
        d2, idx = nearest_sq_distances(moved, target)
        matched = torch.gather(target.expand(moved.shape[0], *target.shape[-2:]), 1,
                               idx.unsqueeze(-1).expand(*idx.shape, 3))
        weights = torch.ones_like(d2) if max_distance is None else (d2 <= max_distance ** 2).to(d2.dtype)
        ok = weights.sum(-1) >= 3
        new_rot, new_trans = procrustes(source.expand(moved.shape[0], *source.shape[-2:]), matched, weights)
        rotation = torch.where(ok[:, None, None], new_rot, rotation)
        translation = torch.where(ok[:, None], new_trans, translation)
    return rotation, translation
