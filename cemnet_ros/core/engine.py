"""The differentiable cross-entropy method guided by the sampling network (CEMNet)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import torch
from torch import nn

from .config import CEMConfig
from .network import SamplingNetwork
from .scoring import CandidateScorer
from .sparsemax import sparsemax


@dataclass
class CEMOutput:
    """Final Gaussian (mu_T, sigma_T) and the initial one (mu0, sigma0); all (B, 6)."""

    mu: torch.Tensor
    sigma: torch.Tensor
    mu0: torch.Tensor
    sigma0: torch.Tensor


class CEMNet(nn.Module):
    """Sample N candidates from N(mu, sigma), score them, weight them by sparsemax, refit; T times.

    Candidates are reparameterised (mu + sigma * noise), so gradients reach mu0 and sigma0, hence the
    sampling network; the scores themselves carry no gradient.
    """

    def __init__(self, cem: CEMConfig | None = None, network: Optional[SamplingNetwork] = None,
                 prior_sigma: tuple[float, ...] = (1.0,) * 6):
        super().__init__()
        self.cem = cem or CEMConfig()
        self.network = network
        self.register_buffer("prior_sigma", torch.tensor(prior_sigma, dtype=torch.float32), persistent=False)

    def initial_distribution(self, source: torch.Tensor, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """mu0, sigma0 from the sampling network, or N(0, prior_sigma) without one."""
        if self.network is not None:
            return self.network(source, target)
        b = source.shape[0]
        return source.new_zeros(b, 6), self.prior_sigma.to(source).expand(b, 6)

    def forward(self, source: torch.Tensor, target: torch.Tensor, mu0: torch.Tensor | None = None,
                sigma0: torch.Tensor | None = None, generator: torch.Generator | None = None) -> CEMOutput:
        """source (B, n, 3), target (B, m, 3); mu0/sigma0 (B, 6) override the initial distribution."""
        cem = self.cem
        if mu0 is None or sigma0 is None:
            mu0, sigma0 = self.initial_distribution(source, target)
        mu, sigma = mu0, sigma0
        if cem.exploration_weight > 0:
            w = cem.exploration_weight
            mu = (1.0 - w) * mu
            sigma = (1.0 - w) * sigma + w * sigma.new_tensor(cem.exploration_sigma)
        scorer = CandidateScorer(source, target, cem)
        b = source.shape[0]
        for k in range(cem.n_iters):
            noise = torch.randn(b, cem.n_candidates, 6, generator=generator, device=source.device, dtype=mu.dtype)
            candidates = mu.unsqueeze(1) + sigma.unsqueeze(1) * noise
            weights = sparsemax(-scorer.cost(candidates, fused=k < cem.n_fused_iters), dim=1).unsqueeze(-1)
            mu = (weights * candidates).sum(1)
            sigma = ((weights * (candidates - mu.unsqueeze(1)).square()).sum(1) + 1e-12).sqrt()
        return CEMOutput(mu, sigma, mu0, sigma0)
