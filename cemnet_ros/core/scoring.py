"""Scores CEM candidates of a batch of pairs: the cost D^mc, optionally fused with the after-ICP cost.

Two interchangeable back ends: numba grid kernels on the CPU (:mod:`.nn_grid`) and brute-force torch on
CUDA. Scores never carry gradients (the reference detaches them as well).
"""
from __future__ import annotations

import numpy as np
import torch
from scipy.spatial import cKDTree

from . import nn_grid
from .config import CEMConfig
from .geometry_torch import action_to_rt, procrustes, transform_points
from .icp import batch_icp
from .rewards import max_consensus_reward

LATTICE_SPACING = CEMConfig.lattice_spacing  # default spacing (units of epsilon), for callers without a config


class CandidateScorer:
    """Costs of candidate actions (B, N, 6) for fixed source (B, n, 3) and target (B, m, 3) clouds."""

    def __init__(self, source: torch.Tensor, target: torch.Tensor, cem: CEMConfig):
        self.cem = cem
        self.source, self.target = source.detach(), target.detach()
        self.on_cpu = source.device.type == "cpu"
        if self.on_cpu:  # rewards are sums over points: any order gives them, Z-order gives them fastest
            spacing = cem.epsilon * cem.lattice_spacing
            self._src_np, self._src_grids = _prepare_each(self.source, cem.epsilon, spacing)
            self._tgt_np, self._tgt_grids = _prepare_each(self.target, cem.epsilon, spacing)
            self._icp_grids: list | None = None  # built on the first fused iteration only

    def _icp_grid(self, b: int):
        if self._icp_grids is None:
            spacing = self.cem.epsilon * self.cem.lattice_spacing
            _, self._icp_grids = _prepare_each(self.target, self.cem.icp_radius, spacing, self._tgt_np)
        return self._icp_grids[b]

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
            return nn_grid.fused_batch(self._src_np[b], self._tgt_np[b], self._src_grids[b], self._icp_grid(b), rot,
                                       trans, cem.epsilon, cem.icp_radius, cem.icp_steps, cem.alpha)
        return nn_grid.consensus_batch(self._src_np[b], self._tgt_np[b], self._tgt_grids[b], self._src_grids[b], rot,
                                       trans, cem.epsilon)

    def _reward_torch(self, b: int, rot: torch.Tensor, trans: torch.Tensor, fused: bool) -> torch.Tensor:
        src, tgt = self.source[b].double().unsqueeze(0), self.target[b].double().unsqueeze(0)
        now = max_consensus_reward(transform_points(src, rot, trans), tgt, self.cem.epsilon)
        if not fused:
            return now
        rot, trans = batch_icp(src, tgt, rot, trans, self.cem.icp_steps, self.cem.icp_radius)
        after = max_consensus_reward(transform_points(src, rot, trans), tgt, self.cem.epsilon)
        return self.cem.alpha * now + (1.0 - self.cem.alpha) * after


def _prepare_each(clouds: torch.Tensor, radius: float, spacing: float, ordered: list | None = None
                  ) -> tuple[list, list]:
    """Z-ordered float64 copies of a batch's clouds and their lattices; built once for a broadcast batch.

    A batch made by ``expand`` (stride 0: every pair shares one cloud, e.g. hypotheses of one scan pair)
    gets one lattice, referenced B times.
    """
    shared = clouds.shape[0] > 1 and clouds.stride(0) == 0
    count = 1 if shared else clouds.shape[0]
    if ordered is None:
        ordered = [_in_locality_order(clouds[b].double().numpy()) for b in range(count)]
    grids = [nn_grid.build_grid(points, radius, spacing).astuple() for points in ordered[:count]]
    if shared:
        return ordered[:1] * clouds.shape[0], grids * clouds.shape[0]
    return ordered, grids


def _in_locality_order(points: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(points[nn_grid.locality_order(points)], dtype=np.float64)


def refine_with_icp(source: np.ndarray, target: np.ndarray, rotation: np.ndarray, translation: np.ndarray,
                    steps: int, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Optional final point-to-point ICP refinement of one motion (exact k-d tree correspondences within radius)."""
    tree = cKDTree(target)
    source_t = torch.as_tensor(source, dtype=torch.float64)
    for _ in range(steps):
        dist, idx = tree.query(source @ rotation.T + translation, distance_upper_bound=radius)
        inliers = np.isfinite(dist)
        if inliers.sum() < 3:
            break
        matched = torch.as_tensor(target[idx[inliers]], dtype=torch.float64)
        rot, trans = procrustes(source_t[inliers][None], matched[None])
        rotation, translation = rot[0].numpy(), trans[0].numpy()
    return rotation, translation


def consensus_fitness(source: np.ndarray, target: np.ndarray, rotation: np.ndarray, translation: np.ndarray,
                      epsilon: float) -> float:
    """Fitness in [0, 1]: the max-consensus reward of one motion divided by 2."""
    src = np.ascontiguousarray(source, dtype=np.float64)
    tgt = np.ascontiguousarray(target, dtype=np.float64)
    spacing = epsilon * LATTICE_SPACING
    reward = nn_grid.consensus_batch(src, tgt, nn_grid.build_grid(tgt, epsilon, spacing).astuple(),
                                     nn_grid.build_grid(src, epsilon, spacing).astuple(),
                                     np.ascontiguousarray(rotation, dtype=np.float64)[None],
                                     np.ascontiguousarray(translation, dtype=np.float64)[None], epsilon)
    return float(reward[0]) / 2.0
