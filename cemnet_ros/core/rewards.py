"""Alignment rewards on torch tensors (brute force: the CUDA path and the reference for tests).

``D^mc`` is the paper's max-consensus distance: ``2 - mean_x max(0, 1 - d(x, Y)/eps) - mean_y max(0, 1 - d(y, X)/eps)``,
0 for a perfect overlap and 2 when nothing lies within ``eps``. With ``eps`` at least every nearest-neighbour
distance it equals the (non-squared) Chamfer distance divided by ``eps`` (the paper's lemma).
"""
from __future__ import annotations

import torch

CHUNK_ELEMENTS = 1 << 25  # pairwise distances held at once (~128 MB of float32)


def nearest_sq_distances(query: torch.Tensor, reference: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(..., n, 3), (..., m, 3) -> squared distance to and index of each query point's nearest reference point."""
    batch_shape = torch.broadcast_shapes(query.shape[:-2], reference.shape[:-2])
    query = query.expand(*batch_shape, *query.shape[-2:]).reshape(-1, *query.shape[-2:])
    reference = reference.expand(*batch_shape, *reference.shape[-2:]).reshape(-1, *reference.shape[-2:])
    per_item = query.shape[1] * reference.shape[1]
    step = max(1, CHUNK_ELEMENTS // max(per_item, 1))
    dists, idxs = [], []
    for i in range(0, query.shape[0], step):
        d2 = torch.cdist(query[i:i + step], reference[i:i + step]).square()
        best = d2.min(-1)
        dists.append(best.values)
        idxs.append(best.indices)
    shape = (*batch_shape, query.shape[1])
    return torch.cat(dists).reshape(shape), torch.cat(idxs).reshape(shape)


def max_consensus_reward(source: torch.Tensor, target: torch.Tensor, epsilon: float) -> torch.Tensor:
    """Two-way truncated inlier reward in [0, 2] of aligned clouds (..., n, 3) and (..., m, 3)."""
    d_src = nearest_sq_distances(source, target)[0].sqrt()
    d_tgt = nearest_sq_distances(target, source)[0].sqrt()
    score = lambda d: (1.0 - d / epsilon).clamp_min(0.0).mean(-1)  # noqa: E731
    return score(d_src) + score(d_tgt)


