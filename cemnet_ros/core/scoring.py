"""Scores CEM candidates of a batch of pairs: the cost D^mc, optionally fused with the after-ICP cost.

Two interchangeable back ends: numba look-up lattices on the CPU (:mod:`.lattice_rewards`) and brute-force torch
on CUDA. Scores never carry gradients (the reference detaches them as well).
"""
from __future__ import annotations

import numpy as np
import torch

from .config import CEMConfig
from .geometry_torch import action_to_rt, transform_points
from .icp_torch import batch_icp
from .lattice import Lattice, build_lattice, locality_order
from .lattice_rewards import LatticePair
from .rewards import max_consensus_reward


class CandidateScorer:
    """Costs of candidate actions (B, N, 6) for fixed source (B, n, 3) and target (B, m, 3) clouds."""

    def __init__(self, source: torch.Tensor, target: torch.Tensor, cem: CEMConfig):
        self.cem = cem
        self.source, self.target = source.detach(), target.detach()
        self.on_cpu = source.device.type == "cpu"
        if self.on_cpu:  # rewards are sums over points: any order gives them, Z-order gives them fastest
            spacing = cem.epsilon * cem.lattice_spacing
            sources = _lattices(self.source, cem.epsilon, spacing)
            targets = _lattices(self.target, cem.epsilon, spacing)
            self._pairs = [LatticePair(s, t) for s, t in zip(sources, targets)]
            self._with_icp_targets = False  # built on the first fused iteration only

    def _fused_pair(self, b: int) -> LatticePair:
        if not self._with_icp_targets:
            spacing = self.cem.epsilon * self.cem.lattice_spacing
            clouds = [pair.target.cloud for pair in self._pairs]
            for pair, icp_target in zip(self._pairs, _lattices(self.target, self.cem.icp_radius, spacing, clouds)):
                pair.icp_target = icp_target
            self._with_icp_targets = True
        return self._pairs[b]

    def cost(self, candidates: torch.Tensor, fused: bool) -> torch.Tensor:
        """(B, N, 6) -> (B, N) cost 2 - reward; ``fused``: alpha * now + (1 - alpha) * after ICP."""
        fused = fused and self.cem.icp_steps > 0
        with torch.no_grad():
            # A non-finite candidate (from a diverged mu/sigma) would index the lattice at random: score it as
            # the worst motion instead (reward 0).
            finite = torch.isfinite(candidates.detach()).all(-1)
            rot, trans = action_to_rt(torch.where(finite.unsqueeze(-1), candidates.detach(), 0.0).double())
            if self.on_cpu:
                reward = torch.from_numpy(np.stack([self._reward_cpu(b, rot[b].numpy(), trans[b].numpy(), fused)
                                                    for b in range(rot.shape[0])]))
            else:
                reward = torch.stack([self._reward_torch(b, rot[b], trans[b], fused) for b in range(rot.shape[0])])
            reward = torch.where(finite.to(reward.device), reward, 0.0)
        return (2.0 - reward).to(candidates.dtype)

    def _reward_cpu(self, b: int, rot: np.ndarray, trans: np.ndarray, fused: bool) -> np.ndarray:
        rot, trans = np.ascontiguousarray(rot), np.ascontiguousarray(trans)
        cem = self.cem
        if fused:
            return self._fused_pair(b).fused_rewards(rot, trans, cem.epsilon, cem.icp_radius, cem.icp_steps, cem.alpha)
        return self._pairs[b].rewards(rot, trans, cem.epsilon)

    def _reward_torch(self, b: int, rot: torch.Tensor, trans: torch.Tensor, fused: bool) -> torch.Tensor:
        src, tgt = self.source[b].double().unsqueeze(0), self.target[b].double().unsqueeze(0)
        now = max_consensus_reward(transform_points(src, rot, trans), tgt, self.cem.epsilon)
        if not fused:
            return now
        rot, trans = batch_icp(src, tgt, rot, trans, self.cem.icp_steps, self.cem.icp_radius)
        after = max_consensus_reward(transform_points(src, rot, trans), tgt, self.cem.epsilon)
        return self.cem.alpha * now + (1.0 - self.cem.alpha) * after


def _lattices(clouds: torch.Tensor, radius: float, spacing: float, ordered: list | None = None) -> list[Lattice]:
    """Lattices of a batch's clouds (Z-ordered float64 copies, or ``ordered``); built once for a broadcast batch.

    A batch made by ``expand`` (stride 0: every pair shares one cloud, e.g. hypotheses of one scan pair)
    gets one lattice, referenced B times.
    """
    shared = clouds.shape[0] > 1 and clouds.stride(0) == 0
    count = 1 if shared else clouds.shape[0]
    if ordered is None:
        ordered = [_in_locality_order(clouds[b].double().numpy()) for b in range(count)]
    lattices = [build_lattice(points, radius, spacing) for points in ordered[:count]]
    return lattices * clouds.shape[0] if shared else lattices


def _in_locality_order(points: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(points[locality_order(points)], dtype=np.float64)
