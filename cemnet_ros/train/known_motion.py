"""Self-supervised training of the sampling network alone, on pairs whose answer the trainer made.

A pair of one scan (or shape) and a copy of it moved by a random motion the trainer drew knows its motion with no
label from anyone. The network is taught it directly (no CEM in the loop, so a step costs one forward and
backward pass of the network, not N x T reward evaluations): its soft matching should pick each source point's
true nearest target point, its mean mu0 should move the source onto where it truly lies, and its sigma0 should be
the spread of mu0's errors (a Gaussian likelihood), because the recovery draws its prior candidates from
N(mu0, sigma0). Pairs of two different scans carry no such answer and are left out of these terms.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from cemnet_ros.core.geometry_torch import action_to_rt, matrix_to_euler, transform_points
from cemnet_ros.core.network import Prediction
from cemnet_ros.core.rewards import nearest_sq_distances
from cemnet_ros.schema import param, validate


@dataclass
class KnownMotionConfig:
    """Weights and scales of the known-motion objective (``objective: known_motion``)."""

    match_radius: float = param(0.05, "a source point is taught its true nearest target point when that lies within "
                                "this distance (network units) of where it truly lies", low=1e-6)
    pose_weight: float = param(1.0, "weight of mu0's alignment error (mean distance, network units, between the "
                               "source moved by mu0 and by the true motion)", low=0.0)
    sigma_weight: float = param(0.1, "weight of the Gaussian negative log-likelihood of mu0's error under sigma0",
                                low=0.0)

    def __post_init__(self) -> None:
        validate(self)


def known_motion_losses(source: torch.Tensor, target: torch.Tensor, rotation: torch.Tensor,
                        translation: torch.Tensor, known: torch.Tensor, prediction: Prediction,
                        config: KnownMotionConfig) -> dict[str, torch.Tensor]:
    """The terms (``total``, ``match``, ``pose``, ``sigma``) over the pairs with ``known`` (B,) motions
    ``target ~ rotation @ source + translation``; the other pairs' (NaN) truths are never touched."""
    keep = known.bool()
    source, target, prediction = source[keep], target[keep], Prediction(*(x[keep] for x in prediction))
    rotation, translation = rotation[keep].to(source.dtype), translation[keep].to(source.dtype)
    if len(source) == 0:
        zero = prediction.mu0.sum() * 0.0  # no pair to learn from: a zero that backward still accepts
        return {"total": zero, "match": zero, "pose": zero, "sigma": zero}
    truly = transform_points(source, rotation, translation)
    match = matching_loss(truly, target, prediction.match, config.match_radius)
    pose = (transform_points(source, *action_to_rt(prediction.mu0)) - truly).norm(dim=-1).mean()
    sigma = gaussian_nll(action_error(rotation, translation, prediction.mu0.detach()), prediction.sigma0)
    total = match + config.pose_weight * pose + config.sigma_weight * sigma
    return {"total": total, "match": match, "pose": pose, "sigma": sigma}


def matching_loss(truly: torch.Tensor, target: torch.Tensor, match: torch.Tensor, radius: float) -> torch.Tensor:
    """Cross-entropy of each match row against the target point nearest to where its source point truly lies
    (``truly``), over the points that have one within ``radius``."""
    with torch.no_grad():
        sq, nearest = nearest_sq_distances(truly, target)
        has_partner = sq < radius * radius
    picked = match.gather(2, nearest.unsqueeze(-1)).squeeze(-1)
    return -(picked.clamp_min(1e-12).log() * has_partner).sum() / has_partner.sum().clamp_min(1)


def action_error(rotation: torch.Tensor, translation: torch.Tensor, mu0: torch.Tensor) -> torch.Tensor:
    """(B, 6) true action minus mu0, the angles wrapped into [-pi, pi)."""
    error = torch.cat([matrix_to_euler(rotation), translation], -1) - mu0
    angles = torch.remainder(error[:, :3] + torch.pi, 2.0 * torch.pi) - torch.pi
    return torch.cat([angles, error[:, 3:]], -1)


def gaussian_nll(error: torch.Tensor, sigma: torch.Tensor) -> torch.Tensor:
    """Mean over pairs of the negative log-likelihood (constants dropped) of ``error`` under N(0, diag(sigma^2))."""
    return (sigma.log() + 0.5 * (error / sigma).square()).sum(-1).mean()
