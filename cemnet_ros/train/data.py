"""Training data: registration pairs made on the fly from shapes, a folder of scans or a bag (:mod:`.scan_pairs`).

Every shape pair comes from the evaluation protocol's :func:`make_pair` (random pose, partial crop, optional
noise), seeded by ``(seed, epoch, index)`` (:mod:`.seeded_pairs`): each epoch sees new poses, yet any run is
reproducible and a resumed run draws exactly the pairs the uninterrupted run would have drawn. Validation pairs
ignore the epoch.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset
from tqdm import tqdm

from cemnet_ros.eval.protocol import ProtocolConfig, load_shapes, make_pair
from cemnet_ros.io.pointcloud_files import read_points

from .bag_scans import read_bag_scans, split_in_time
from .config import TrainConfig, bag_paths
from .scan_pairs import BagsPairs, ScanPairDataset
from .seeded_pairs import SeededPairs, pair_item

SCAN_SUFFIXES = (".ply", ".pcd", ".npy", ".npz", ".bin")


class PairDataset(SeededPairs):
    """Pairs from ``shapes`` (S, n, 3) by the evaluation protocol, seeded as :class:`SeededPairs` says; items as
    :func:`pair_item` makes them."""

    def __init__(self, shapes: np.ndarray, protocol: ProtocolConfig, seed: int, fixed: bool = False):
        super().__init__(seed, fixed)
        shapes = np.asarray(shapes, dtype=np.float32)
        if shapes.ndim != 3 or shapes.shape[2] != 3 or len(shapes) == 0:
            raise ValueError(f"shapes must be a non-empty (S, n, 3) array, got {shapes.shape}")
        if not np.isfinite(shapes).all():
            raise ValueError("shapes contain NaN/inf coordinates")
        self.shapes = shapes
        self.protocol = protocol

    def __len__(self) -> int:
        return len(self.shapes)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        pair = make_pair(self.shapes[index], self.rng(index), self.protocol)
        return pair_item(pair.source, pair.target, pair.rotation, pair.translation, known_motion=True)


def normalise_unit_sphere(points: np.ndarray) -> np.ndarray:
    """Centre ``points`` on their centroid and scale them into the unit sphere (as ModelNet shapes)."""
    centred = points - points.mean(axis=0)
    radius = float(np.linalg.norm(centred, axis=1).max())
    if radius <= 0.0:
        raise ValueError("all points coincide; cannot normalise")
    return (centred / radius).astype(np.float32)


def load_scan_shapes(folder: str | Path, n_keep: int, seed: int, progress: bool = True
                     ) -> tuple[np.ndarray, list[Path]]:
    """Read every scan in ``folder`` (PLY/PCD/NPY/NPZ/KITTI .bin), keep ``n_keep`` random finite points of each
    (seeded per file index) and normalise it to the unit sphere. Scans with too few points are skipped."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"scan folder not found: {folder}")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in SCAN_SUFFIXES)
    if not files:
        raise ValueError(f"no scans ({', '.join(SCAN_SUFFIXES)}) in {folder}")
    shapes, kept = [], []
    for i, path in enumerate(tqdm(files, desc="reading scans", disable=not progress)):
        points = read_points(path)  # (n, 3) float64, finite rows only
        if len(points) < n_keep:
            warnings.warn(f"skipping {path.name}: {len(points)} finite points < {n_keep}")
            continue
        rng = np.random.default_rng([seed, i])
        shapes.append(normalise_unit_sphere(points[rng.choice(len(points), n_keep, replace=False)]))
        kept.append(path)
    if not shapes:
        raise ValueError(f"no scan in {folder} has {n_keep} finite points")
    return np.stack(shapes), kept


def drop_duplicates(shapes: np.ndarray) -> np.ndarray:
    """``shapes`` without exact repeats (first kept, with a warning): a repeat on both sides of the
    train/validation split would leak."""
    seen: dict[bytes, int] = {}
    for i, shape in enumerate(shapes):
        seen.setdefault(np.ascontiguousarray(shape).tobytes(), i)
    keep = np.sort(np.fromiter(seen.values(), dtype=int))
    if len(keep) < len(shapes):
        warnings.warn(f"dropped {len(shapes) - len(keep)} exact duplicate shape(s)")
    return shapes[keep]


def split_train_val(n: int, val_fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Seeded disjoint index sets (train, val); val gets round(n * val_fraction) >= 1 items."""
    if n < 2:
        raise ValueError(f"need at least 2 shapes/scans to hold some out for validation, got {n}")
    order = np.random.default_rng([seed, 7]).permutation(n)
    n_val = min(n - 1, max(1, int(round(n * val_fraction))))
    return np.sort(order[n_val:]), np.sort(order[:n_val])


def _limit(indices: np.ndarray, limit: int) -> np.ndarray:
    """The first ``limit`` indices; all of them for ``limit`` 0."""
    return indices[:limit] if limit > 0 else indices


def build_datasets(config: TrainConfig) -> tuple[Dataset, Dataset]:
    """(train, val) pair datasets from ``config.data`` or ``config.bag``: validation holds out shapes of the
    *train* split (the test split stays untouched for the final evaluation), or the last scans of the bag."""
    if config.bag:
        return build_bag_datasets(config)
    if not config.data:
        raise ValueError("nothing to train on: give data (an .npz of shapes or a folder of scans) or bag")
    path = Path(config.data)
    if path.is_dir():
        shapes, _ = load_scan_shapes(path, config.protocol.n_points, config.seed, config.progress)
    elif path.suffix == ".npz" and path.is_file():
        shapes, _ = load_shapes(path, split="train", unseen=config.unseen)
    else:
        raise FileNotFoundError(f"--data must be an .npz of shapes or a folder of scans: {path}")
    if shapes.shape[1] < config.protocol.n_points:
        raise ValueError(f"shapes have {shapes.shape[1]} points, the protocol needs {config.protocol.n_points}")
    shapes = drop_duplicates(shapes)
    train_idx, val_idx = split_train_val(len(shapes), config.val_fraction, config.seed)
    train_idx, val_idx = _limit(train_idx, config.limit_train), _limit(val_idx, config.limit_val)
    return (PairDataset(shapes[train_idx], config.protocol, config.seed),
            PairDataset(shapes[val_idx], config.protocol, config.seed, fixed=True))


def build_bag_datasets(config: TrainConfig) -> tuple[ScanPairDataset | BagsPairs, ScanPairDataset | BagsPairs]:
    """(train, val) scan pairs of the bags of ``config.bag``, each in its own units (as the node measures them);
    validation holds out the last scans of each bag."""
    train, val = [], []
    for k, bag in enumerate(bag_paths(config)):
        scans = read_bag_scans(bag, config.topic, config.preprocess, config.progress)
        train_idx, val_idx = split_in_time(len(scans), config.val_fraction)
        train_idx, val_idx = _limit(train_idx, config.limit_train), _limit(val_idx, config.limit_val)
        seed = config.seed + k  # distinct draws for the same scan index of another bag
        train.append(ScanPairDataset(scans.part(train_idx), config.preprocess, config.scans, seed))
        val.append(ScanPairDataset(scans.part(val_idx), config.preprocess, config.scans, seed, fixed=True))
    return (train[0], val[0]) if len(train) == 1 else (BagsPairs(train), BagsPairs(val))
