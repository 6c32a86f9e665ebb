"""Unsupervised training loss: Geman-McClure robust distance between the aligned clouds, both directions."""
from __future__ import annotations

import torch

from .rewards import nearest_sq_distances


def geman_mcclure_loss(aligned: torch.Tensor, target: torch.Tensor, mu: float = 0.01) -> torch.Tensor:
    """mean over the batch of mean_x rho(d(x, Y)^2) + mean_y rho(d(y, X)^2), rho(s) = mu s / (s + mu).

    Gradients flow through the aligned source (nearest neighbours are re-found, not differentiated).
    """
    def rho(sq: torch.Tensor) -> torch.Tensor:
        return mu * sq / (sq + mu)

    with torch.no_grad():
        idx_src = nearest_sq_distances(aligned, target)[1]
        idx_tgt = nearest_sq_distances(target, aligned)[1]
    nearest_tgt = torch.gather(target, -2, idx_src.unsqueeze(-1).expand(*idx_src.shape, 3))
    nearest_src = torch.gather(aligned, -2, idx_tgt.unsqueeze(-1).expand(*idx_tgt.shape, 3))
    loss = (rho((aligned - nearest_tgt).square().sum(-1)).mean(-1)
            + rho((target - nearest_src).square().sum(-1)).mean(-1))
    return loss.mean()
