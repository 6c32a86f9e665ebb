"""Tiny synthetic training data for the training tests: asymmetric unions of boxes (160 points, partial crops of
96), few candidates, so that a test trains in seconds on 2 cores."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from cemnet_ros.core.config import UNSEEDED, CEMConfig
from cemnet_ros.eval.protocol import ProtocolConfig
from cemnet_ros.train.config import ScanPairConfig, TrainConfig

TINY = ProtocolConfig(n_points=160, n_partial=96)


def box_union_shapes(n_shapes: int, n_points: int, seed: int) -> np.ndarray:
    """Asymmetric shapes: points on the surfaces of 3 random boxes each, shuffled, in the unit sphere."""
    rng = np.random.default_rng(seed)
    shapes = []
    for _ in range(n_shapes):
        parts = []
        for box in range(3):
            size = rng.uniform(0.2, 1.0, 3)
            centre = rng.uniform(-0.6, 0.6, 3)
            pts = rng.uniform(-0.5, 0.5, (n_points, 3))
            axis = rng.integers(0, 3, n_points)
            pts[np.arange(n_points), axis] = rng.choice([-0.5, 0.5], n_points)  # onto a face
            parts.append(pts * size + centre)
        pts = np.concatenate(parts)[rng.permutation(3 * n_points)[:n_points]]
        pts -= pts.mean(0)
        shapes.append(pts / np.linalg.norm(pts, axis=1).max())
    return np.stack(shapes).astype(np.float32)


def tiny_config(data: Path, out: Path, **overrides) -> TrainConfig:
    cem = CEMConfig(n_candidates=24, n_iters=3, n_fused_iters=0, exploration_weight=0.0, seed=UNSEEDED)
    val_cem = CEMConfig(n_candidates=24, n_iters=3, n_fused_iters=1)
    base = TrainConfig(data=str(data), out_dir=str(out), batch_size=4, lr=1e-3, epochs=1, cem=cem, val_cem=val_cem,
                       protocol=TINY, val_fraction=0.2, threads=1, progress=False, seed=5)
    return replace(base, **overrides)


def bag_config(bag: Path, out: Path, **overrides) -> TrainConfig:
    """A training config on ``bag`` small enough for a test: 128 points, CEMs of 24 x 3, batch 4."""
    cem = CEMConfig(n_candidates=24, n_iters=3, n_fused_iters=0, exploration_weight=0.0, seed=UNSEEDED)
    val_cem = CEMConfig(n_candidates=24, n_iters=3, n_fused_iters=0)  # no fused kernels to compile
    base = TrainConfig(bag=str(bag), out_dir=str(out), batch_size=4, lr=1e-3, epochs=1, cem=cem, val_cem=val_cem,
                       scans=ScanPairConfig(n_points=128), val_fraction=0.25, threads=1, progress=False, seed=5)
    return replace(base, **overrides)
