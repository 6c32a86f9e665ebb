"""Training pairs from the scans of a bag, in the node's units: what the recovery meets, with known truth when
the bag has ground truth.

Pairs are seeded by (seed, epoch, index) as the shape pairs (:mod:`.seeded_pairs`): every epoch brings new
motions, crops and subsets, yet every run draws the same ones.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Optional

import numpy as np
import torch
from torch.utils.data import Dataset

from cemnet_ros.core.geometry import action_to_matrix_np, apply_transform
from cemnet_ros.core.global_search import scatter
from cemnet_ros.pipeline.config import PreprocessConfig, RecoveryConfig
from cemnet_ros.pipeline.steps.frame import near_points, network_units
from cemnet_ros.pipeline.steps.preprocess import subsample

from .bag_scans import ScanSet
from .config import ScanPairConfig
from .seeded_pairs import SeededPairs, pair_item

_ONE_CANDIDATE = dataclasses.replace(RecoveryConfig().search, n_scatter=1, n_hypotheses=1, n_seeds=1)  # its scatter


@dataclass
class ScanPair:
    """Prepared clouds (n, 3) in network units and ``T_target_source`` (4x4, units; None when unknown); one_scan:
    both clouds come from the same scan, so the truth is the random motion alone (no ground truth needed)."""

    source: np.ndarray
    target: np.ndarray
    T_target_source: Optional[np.ndarray]
    one_scan: bool


def recovery_motion(rng: np.random.Generator, radius: float, scale: float) -> np.ndarray:
    """A 4x4 rigid motion (m) drawn as the node's recovery scatters one candidate about the sensor: yaw uniform over
    the full circle, translation uniform on a disc of ``radius`` m, small roll, pitch and height."""
    action = scatter(np.zeros(6), radius / scale, _ONE_CANDIDATE, rng)[0]
    action[3:] *= scale  # the scatter works in network units
    return action_to_matrix_np(action)


def drop_sector(points: np.ndarray, rng: np.random.Generator, max_deg: float, min_points: int) -> np.ndarray:
    """``points`` without a random azimuth sector (about the sensor's z axis) of up to ``max_deg`` degrees: a
    partial view. The cloud stays whole when fewer than ``min_points`` would remain."""
    start, width = rng.uniform(-np.pi, np.pi), np.radians(rng.uniform(0.0, max_deg))
    inside = np.mod(np.arctan2(points[:, 1], points[:, 0]) - start, 2.0 * np.pi) < width
    return points if np.count_nonzero(~inside) < min_points else points[~inside]


def exactly(points: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """``points`` (at most ``n``) topped up to ``n`` rows with random repeats, so that pairs stack into batches."""
    if len(points) >= n:
        return points[:n]
    return np.concatenate([points, points[rng.integers(0, len(points), n - len(points))]])


class ScanPairDataset(SeededPairs):
    """Pairs of a :class:`ScanSet`. Items: source, target (n, 3) float32 in network units; rotation (3, 3) and
    translation (3,) float64 with ``target ~= R source + t`` (NaN when the bag has no ground truth for a pair of
    two scans; validation, ``fixed``, then pairs each scan with itself only)."""

    def __init__(self, scans: ScanSet, preprocess: PreprocessConfig, pairs: ScanPairConfig, seed: int,
                 fixed: bool = False):
        super().__init__(seed, fixed)
        if len(scans) == 0:
            raise ValueError("no scans to make pairs from")
        self.scans, self.preprocess, self.pairs = scans, preprocess, pairs

    def __len__(self) -> int:
        return len(self.scans)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        pair = self.pair(int(index), self.rng(index))
        truth = np.full((4, 4), np.nan) if pair.T_target_source is None else pair.T_target_source
        return pair_item(pair.source, pair.target, truth[:3, :3], truth[:3, 3], known_motion=pair.one_scan)

    def pair(self, index: int, rng: np.random.Generator) -> ScanPair:
        """Scan ``index`` as the target; the source is a scan up to ``max_gap`` away or the same one, moved by a
        :func:`recovery_motion`; both cropped, cut to the CEM's points, noisy, then put into network units
        centred on the target's sensor (as the recovery centres its search) or centroid (``scans.centre``)."""
        scale = self.scans.scale
        other = self._partner(index, rng)
        T_natural = self.scans.relative(index, other)  # metres, the target's from the source's sensor frame
        target = self._cloud(index, rng)
        motion = recovery_motion(rng, self.pairs.radius, scale)
        source = apply_transform(motion, self._cloud(other, rng))
        centre = np.zeros(3) if self.pairs.centre == "sensor" else target.mean(axis=0)
        to_units, from_units = network_units(scale, centre)
        truth = None if T_natural is None else to_units @ T_natural @ np.linalg.inv(motion) @ from_units
        return ScanPair(apply_transform(to_units, source).astype(np.float32),
                        apply_transform(to_units, target).astype(np.float32), truth, one_scan=other == index)

    def _partner(self, index: int, rng: np.random.Generator) -> int:
        """The source scan: ``index`` itself, or (share ``consecutive``; for validation only with ground truth)
        one ``1..max_gap`` scans later (earlier at the end of the set)."""
        two_scans = rng.random() < self.pairs.consecutive and (self.scans.poses is not None or not self.fixed)
        gap = int(rng.integers(1, self.pairs.max_gap + 1))
        if not two_scans or len(self.scans) < 2:
            return index
        other = index + gap if index + gap < len(self.scans) else index - gap
        return int(np.clip(other, 0, len(self.scans) - 1))

    def _cloud(self, index: int, rng: np.random.Generator) -> np.ndarray:
        """Scan ``index`` (m, sensor frame): a sector dropped, the CEM's points (as many as the node takes), noise."""
        cfg, n = self.preprocess, self.pairs.n_points
        partial = drop_sector(self.scans.clouds[index], rng, self.pairs.crop_deg, cfg.min_points)
        near = near_points(partial, cfg, self.scans.scale)
        points = exactly(subsample(near, n, cfg.sampling, int(rng.integers(1 << 31))), n, rng)
        return points + rng.normal(0.0, self.pairs.noise, points.shape)


class BagsPairs(Dataset):
    """The pairs of several bags' :class:`ScanPairDataset` one after another (each bag in its own units)."""

    def __init__(self, parts: list[ScanPairDataset]) -> None:
        self.parts = parts
        self.starts = np.cumsum([0] + [len(part) for part in parts])

    @property
    def fixed(self) -> bool:
        return all(part.fixed for part in self.parts)

    @fixed.setter
    def fixed(self, value: bool) -> None:
        for part in self.parts:
            part.fixed = value

    def set_epoch(self, epoch: int) -> None:
        for part in self.parts:
            part.set_epoch(epoch)

    def __len__(self) -> int:
        return int(self.starts[-1])

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        k = int(np.searchsorted(self.starts, index, side="right")) - 1
        return self.parts[k][int(index - self.starts[k])]
