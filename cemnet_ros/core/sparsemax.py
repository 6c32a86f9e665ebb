"""Sparsemax (Martins & Astudillo, 2016): a projection onto the simplex that yields sparse weights.

The CEM turns candidate scores into weights with it, so that only the best candidates refit the Gaussian.
"""
from __future__ import annotations

import torch


def _sparsemax_forward(z: torch.Tensor, dim: int) -> torch.Tensor:
    z = z - z.max(dim=dim, keepdim=True).values  # shift invariance; improves conditioning
    z_sorted = z.sort(dim=dim, descending=True).values
    k = torch.arange(1, z.shape[dim] + 1, dtype=z.dtype, device=z.device)
    view = [1] * z.dim()
    view[dim] = -1
    k = k.view(view)
    cumsum = z_sorted.cumsum(dim) - 1.0
    support = (k * z_sorted > cumsum).to(z.dtype)
    k_max = support.sum(dim=dim, keepdim=True)
    tau = cumsum.gather(dim, k_max.long() - 1) / k_max
    return (z - tau).clamp_min(0.0)


class _Sparsemax(torch.autograd.Function):
    @staticmethod
    def forward(ctx, z: torch.Tensor, dim: int) -> torch.Tensor:
        p = _sparsemax_forward(z, dim)
        ctx.save_for_backward(p)
        ctx.dim = dim
        return p

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        # Jacobian J = diag(s) - s s^T / |S| with s the support indicator: J v = s * (v - mean_S(v)).
        (p,) = ctx.saved_tensors
        support = (p > 0).to(grad.dtype)
        mean = (grad * support).sum(ctx.dim, keepdim=True) / support.sum(ctx.dim, keepdim=True)
        return support * (grad - mean), None


def sparsemax(z: torch.Tensor, dim: int = -1) -> torch.Tensor:
    """Euclidean projection of ``z`` onto the probability simplex along ``dim`` (exact Jacobian in backward)."""
    return _Sparsemax.apply(z, dim % z.dim())
