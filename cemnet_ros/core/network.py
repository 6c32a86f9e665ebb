"""The sampling network: DGCNN features -> soft matching -> weighted SVD -> (mu0, sigma0).

Architecture exactly as the reference (static-graph DGCNN from DCP, no transformer), so the five
official checkpoints load into it (see :mod:`cemnet_ros.core.checkpoint` for the key mapping).
"""
from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import torch
import torch.nn.functional as F
from scipy.spatial import cKDTree
from torch import nn

from .geometry_torch import matrix_to_euler, procrustes


def knn_indices(points: torch.Tensor, k: int) -> torch.Tensor:
    """(B, n, 3) -> (B, n, k) indices of each point's k nearest neighbours (itself included).

    On the CPU a k-d tree (2x faster than the top-k of the dense distance matrix), elsewhere the dense top-k.
    """
    if points.device.type == "cpu":
        return torch.from_numpy(np.stack([cKDTree(c).query(c, k)[1] for c in points.detach().numpy()]))
    return dense_knn_indices(points, k)


def dense_knn_indices(points: torch.Tensor, k: int) -> torch.Tensor:
    """:func:`knn_indices` by the top-k of all pairwise distances (any device)."""
    sq = (points * points).sum(-1)
    neg_d2 = 2.0 * points @ points.transpose(1, 2) - sq.unsqueeze(2) - sq.unsqueeze(1)
    return neg_d2.topk(k, dim=-1).indices


def edge_features(points: torch.Tensor, k: int) -> torch.Tensor:
    """(B, n, 3) -> (B, k, n, 6) edge features cat(neighbour, centre) of the static k-NN graph, channels last.

    The reference holds edges as (B, C, n, k) and applies 1x1 convolutions; here channels come last, so each
    layer is one matrix product over all edges (about 3x faster than the convolution on a CPU), and the
    neighbour axis comes first, so the max over neighbours reduces over contiguous rows.
    """
    b, n, _ = points.shape
    idx = knn_indices(points, k).transpose(1, 2)  # (B, k, n)
    neighbours = points[torch.arange(b, device=points.device)[:, None, None], idx]
    return torch.cat((neighbours, points.unsqueeze(1).expand(b, k, n, 3)), -1)


class DGCNN(nn.Module):
    """Per-point embedding: four edge convolutions (max over k after each), concatenated, then 1x1 conv."""

    def __init__(self, emb_dims: int = 512, k: int = 20):
        super().__init__()
        self.k = k
        widths = [(6, 64), (64, 64), (64, 128), (128, 256), (512, emb_dims)]
        for i, (c_in, c_out) in enumerate(widths, start=1):
            setattr(self, f"conv{i}", nn.Conv2d(c_in, c_out, kernel_size=1, bias=False))
            setattr(self, f"bn{i}", nn.BatchNorm2d(c_out))

    def forward(self, points: torch.Tensor, conv_bn_relu) -> torch.Tensor:
        """(B, n, 3) -> (B, n, emb_dims). ``conv_bn_relu(conv, bn, x)`` applies one block on channels-last ``x``."""
        x = edge_features(points, self.k)
        pooled = []
        for i in range(1, 5):
            x = conv_bn_relu(getattr(self, f"conv{i}"), getattr(self, f"bn{i}"), x)
            pooled.append(x.amax(dim=1))
        return conv_bn_relu(self.conv5, self.bn5, torch.cat(pooled, -1))


def feature_distances(src_emb: torch.Tensor, tgt_emb: torch.Tensor) -> torch.Tensor:
    """(B, n, C), (B, m, C) -> (B, n, m) Euclidean distances between embeddings."""
    d2 = (src_emb * src_emb).sum(-1).unsqueeze(2) + (tgt_emb * tgt_emb).sum(-1).unsqueeze(1) \
        - 2.0 * src_emb @ tgt_emb.transpose(1, 2)
    return d2.clamp_min(1e-12).sqrt()


class Prediction(NamedTuple):
    """The sampling network's output: the CEM's initial Gaussian and the soft matching mu0 comes from."""

    mu0: torch.Tensor  # (B, 6) [z, y, x, tx, ty, tz]
    sigma0: torch.Tensor  # (B, 6) in (0, 1)
    match: torch.Tensor  # (B, n, m) rows: a source point's weights over the target points


class SamplingNetwork(nn.Module):
    """Predicts the CEM's initial Gaussian: mu0 = [z, y, x, tx, ty, tz] and sigma0 in (0, 1)^6."""

    def __init__(self, emb_dims: int = 512, k: int = 20):
        super().__init__()
        self.embedding = DGCNN(emb_dims, k)
        self.sigma_head = nn.Sequential(
            nn.Linear(2 * emb_dims, emb_dims // 4), nn.BatchNorm1d(emb_dims // 4), nn.LeakyReLU(),
            nn.Linear(emb_dims // 4, emb_dims // 8), nn.BatchNorm1d(emb_dims // 8), nn.LeakyReLU(),
            nn.Linear(emb_dims // 8, 6),
        )
        # At inference, BatchNorm uses batch statistics (as the reference, which never calls eval())
        # when True, else the running statistics. Training always uses batch statistics.
        self.batch_stats_at_inference = False

    def _norm(self, bn: Any, x: torch.Tensor) -> torch.Tensor:
        """BatchNorm (``bn``: nn.BatchNorm1d/2d) of ``x`` (M, C), channels last, in the mode that applies (see
        batch_stats_at_inference)."""
        if self.training:
            bn.num_batches_tracked.add_(1)
            return F.batch_norm(x, bn.running_mean, bn.running_var, bn.weight, bn.bias, True, bn.momentum, bn.eps)
        if self.batch_stats_at_inference and x.shape[0] > 1:
            return F.batch_norm(x, None, None, bn.weight, bn.bias, True, 0.0, bn.eps)
        return F.batch_norm(x, bn.running_mean, bn.running_var, bn.weight, bn.bias, False, 0.0, bn.eps)

    def _conv_bn_relu(self, conv: nn.Conv2d, bn: Any, x: torch.Tensor) -> torch.Tensor:
        """relu(bn(conv(x))) of a 1x1 convolution as one matrix product on channels-last ``x`` (..., C_in)."""
        weight = conv.weight.flatten(1)  # (C_out, C_in)
        rows = x.reshape(-1, x.shape[-1])
        if self.training or self.batch_stats_at_inference:
            out = F.relu(self._norm(bn, rows @ weight.t()))
        else:  # running statistics are an affine map: fold them into the product (one pass instead of three)
            scale = bn.weight / (bn.running_var + bn.eps).sqrt()
            out = torch.addmm(bn.bias - bn.running_mean * scale, rows, (weight * scale[:, None]).t()).relu_()
        return out.view(*x.shape[:-1], -1)

    def forward(self, source: torch.Tensor, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """source (B, n, 3), target (B, m, 3) -> mu0 (B, 6), sigma0 (B, 6)."""
        prediction = self.predict(source, target)
        return prediction.mu0, prediction.sigma0

    def predict(self, source: torch.Tensor, target: torch.Tensor) -> Prediction:
        """mu0, sigma0 and the soft matching (B, n, m) behind mu0 (what self-supervised training teaches)."""
        src_emb = self.embedding(source, self._conv_bn_relu)
        tgt_emb = self.embedding(target, self._conv_bn_relu)
        match = torch.softmax(-feature_distances(src_emb, tgt_emb), dim=2)  # (B, n, m)
        rotation, translation = procrustes(source, match @ target)
        mu0 = torch.cat([matrix_to_euler(rotation), translation], -1)
        h = torch.cat([src_emb.amax(dim=1), tgt_emb.amax(dim=1)], 1)  # = max over cat(src, tgt)
        for layer in self.sigma_head:
            h = self._norm(layer, h) if isinstance(layer, nn.BatchNorm1d) else layer(h)
        return Prediction(mu0, torch.sigmoid(h), match)
