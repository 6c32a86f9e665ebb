"""Differentiable torch twins of :mod:`.geometry` (same Euler convention), for the network and the CEM."""
from __future__ import annotations

import torch


def euler_to_matrix(angles: torch.Tensor) -> torch.Tensor:
    """(..., 3) angles [z, y, x] in radians -> (..., 3, 3) rotation matrices (differentiable)."""
    z, y, x = angles.unbind(-1)
    cz, sz, cy, sy, cx, sx = z.cos(), z.sin(), y.cos(), y.sin(), x.cos(), x.sin()
    rows = (
        cy * cz, -cy * sz, sy,
        cx * sz + sx * sy * cz, cx * cz - sx * sy * sz, -sx * cy,
        sx * sz - cx * sy * cz, sx * cz + cx * sy * sz, cx * cy,
    )
    return torch.stack(rows, -1).reshape(*angles.shape[:-1], 3, 3)


def matrix_to_euler(rotation: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) rotation matrices -> (..., 3) angles [z, y, x] (inverse of :func:`euler_to_matrix`)."""
    y = torch.asin(rotation[..., 0, 2].clamp(-1.0, 1.0))
    z = torch.atan2(-rotation[..., 0, 1], rotation[..., 0, 0])
    x = torch.atan2(-rotation[..., 1, 2], rotation[..., 2, 2])
    return torch.stack((z, y, x), -1)


def transform_points(points: torch.Tensor, rotation: torch.Tensor, translation: torch.Tensor) -> torch.Tensor:
    """Apply ``R p + t`` to (..., n, 3) points with (..., 3, 3) rotations and (..., 3) translations.

    Twin of ``geometry.apply_transform``, which takes a 4x4 ``T_target_source``."""
    return points @ rotation.transpose(-1, -2) + translation.unsqueeze(-2)


def action_to_rt(action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(..., 6) action [z, y, x, tx, ty, tz] -> rotation (..., 3, 3), translation (..., 3)."""
    return euler_to_matrix(action[..., :3]), action[..., 3:]


def procrustes(source: torch.Tensor, target: torch.Tensor, weights: torch.Tensor | None = None
               ) -> tuple[torch.Tensor, torch.Tensor]:
    """Batched weighted least-squares rigid fit ``target ~ R source + t`` (Kabsch, reflection-safe).

    source, target: (B, n, 3); weights: (B, n) or None. Returns R (B, 3, 3), t (B, 3). Numpy twin (one pair, no
    weights): ``geometry.procrustes_np``.
    """
    if weights is None:
        weights = torch.ones(source.shape[:-1], dtype=source.dtype, device=source.device)
    w = weights / weights.sum(-1, keepdim=True).clamp_min(1e-12)
    src_mean = (w.unsqueeze(-1) * source).sum(-2)
    tgt_mean = (w.unsqueeze(-1) * target).sum(-2)
    cov = (w.unsqueeze(-1) * (source - src_mean.unsqueeze(-2))).transpose(-1, -2) @ (target - tgt_mean.unsqueeze(-2))
    u, _, vh = torch.linalg.svd(cov)
    v = vh.transpose(-1, -2)
    d = torch.det(v @ u.transpose(-1, -2))
    fix = torch.diag_embed(torch.stack([torch.ones_like(d), torch.ones_like(d), d], -1))
    rotation = v @ fix @ u.transpose(-1, -2)
    translation = tgt_mean - (rotation @ src_mean.unsqueeze(-1)).squeeze(-1)
    return rotation, translation
