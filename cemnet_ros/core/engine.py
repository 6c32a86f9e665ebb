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
    """Final Gaussian (mu_T, sigma_T), the initial one (mu0, sigma0), all (B, 6), and the fitness of mu_T (B,)."""

    mu: torch.Tensor
    sigma: torch.Tensor
    mu0: torch.Tensor
    sigma0: torch.Tensor
    fitness: torch.Tensor  # max-consensus reward of mu_T / 2, in [0, 1]


class CEMNet(nn.Module):
    """Sample N candidates from N(mu, sigma), score them, weight them by sparsemax, refit; T times.

    Candidates are reparameterised (mu + sigma * noise), so gradients reach mu0 and sigma0, hence the
    sampling network; the scores themselves carry no gradient.
    """

    network: Optional[SamplingNetwork]  # submodule and buffer: typed here, as nn.Module's attributes are not
    prior_sigma: torch.Tensor

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

    def explore(self, mu0: torch.Tensor, sigma0: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The reference's test-time blend of the network's Gaussian towards N(0, exploration_sigma)."""
        w = self.cem.exploration_weight
        if w == 0:
            return mu0, sigma0
        return (1.0 - w) * mu0, (1.0 - w) * sigma0 + w * sigma0.new_tensor(self.cem.exploration_sigma)

    def forward(self, source: torch.Tensor, target: torch.Tensor, mu0: torch.Tensor | None = None,
                sigma0: torch.Tensor | None = None, generator: torch.Generator | None = None) -> CEMOutput:
        """source (B, n, 3), target (B, m, 3); mu0/sigma0 (B, 6) given (e.g. a motion model) are used as they are."""
        cem = self.cem
        if mu0 is None or sigma0 is None:
            mu0, sigma0 = self.initial_distribution(source, target)
            mu, sigma = self.explore(mu0, sigma0) if self.network is not None else (mu0, sigma0)
        else:
            mu, sigma = mu0, sigma0
        scorer = CandidateScorer(source, target, cem)
        b = source.shape[0]
        for k in range(cem.n_iters):
            noise = torch.randn(b, cem.n_candidates, 6, generator=generator, device=source.device, dtype=mu.dtype)
            candidates = mu.unsqueeze(1) + sigma.unsqueeze(1) * noise
            weights = sparsemax(-scorer.cost(candidates, fused=k < cem.n_fused_iters), dim=1).unsqueeze(-1)
            mu = (weights * candidates).sum(1)
            sigma = ((weights * (candidates - mu.unsqueeze(1)).square()).sum(1) + 1e-12).sqrt()
        fitness = 1.0 - scorer.cost(mu.unsqueeze(1), fused=False).squeeze(1) / 2.0
        return CEMOutput(mu, sigma, mu0, sigma0, fitness)
