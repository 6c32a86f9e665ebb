"""What the training pair datasets share: pair i of epoch e is drawn from ``default_rng([seed, e + 1, i])``
(validation, ``fixed``: e = -1 always), so every epoch brings new pairs, yet any run, and any resumed run, draws
exactly the same ones; and the items' layout."""
from __future__ import annotations

import numpy as np
import torch
from torch.utils.data import Dataset

VAL_EPOCH = -1  # the "epoch" that seeds validation pairs, so they never change


class SeededPairs(Dataset):
    """Base of the pair datasets: the seed, the epoch and the validation mode (``fixed``)."""

    def __init__(self, seed: int, fixed: bool):
        self.seed = int(seed)
        self.fixed = fixed  # validation: the same pairs every epoch
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        """Select the pairs of ``epoch`` (call before iterating; DataLoader workers see it at fork)."""
        self.epoch = int(epoch)

    def rng(self, index: int) -> np.random.Generator:
        """The generator of item ``index`` in the current epoch."""
        return np.random.default_rng([self.seed, (VAL_EPOCH if self.fixed else self.epoch) + 1, int(index)])


def pair_item(source: np.ndarray, target: np.ndarray, rotation: np.ndarray, translation: np.ndarray,
              known_motion: bool) -> dict[str, torch.Tensor]:
    """An item: source, target (n, 3) float32; rotation (3, 3) and translation (3,) float64, target ~= R src + t;
    known_motion: whether that truth is the random motion the pair was made with (one cloud and a moved copy),
    which self-supervised training may learn from, rather than a label (ground truth)."""
    return {"source": torch.as_tensor(source, dtype=torch.float32),
            "target": torch.as_tensor(target, dtype=torch.float32),
            "rotation": torch.as_tensor(rotation, dtype=torch.float64),
            "translation": torch.as_tensor(translation, dtype=torch.float64),
            "known_motion": torch.tensor(known_motion)}
