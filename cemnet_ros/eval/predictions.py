"""Each method's answers for a list of pairs, timed: CEMNet in batches, the classical baselines pair by pair."""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Sequence, Tuple

import numpy as np
import torch
from tqdm import tqdm

from cemnet_ros.core.registration import BatchRegistrationResult
from cemnet_ros.eval.baselines import fpfh_ransac, icp
from cemnet_ros.eval.protocol import RegistrationPair

Solver = Callable[[np.ndarray, np.ndarray], Tuple[np.ndarray, np.ndarray]]
BASELINES: Dict[str, Solver] = {"icp": icp, "fpfh": fpfh_ransac}


@dataclass
class Prediction:
    """One method's answer for one pair: ``target ~= rotation @ source + translation``."""

    rotation: np.ndarray
    translation: np.ndarray
    seconds: float
    extra: Dict[str, Any] = field(default_factory=dict)


def _stack(pairs: Sequence[RegistrationPair], side: str) -> torch.Tensor:
    return torch.from_numpy(np.stack([getattr(p, side) for p in pairs]))


def _batch_predictions(result: BatchRegistrationResult, seconds_per_pair: float) -> List[Prediction]:
    """``Registrar.register_batch``'s result, one Prediction per pair."""
    return [Prediction(result.rotation[b], result.translation[b], seconds_per_pair,
                       {"fitness": float(result.fitness[b]), "sigma": result.sigma[b].tolist(),
                        "mu0": result.mu0[b].tolist()})
            for b in range(len(result.rotation))]


def run_cemnet(registrar, pairs: Sequence[RegistrationPair], batch_size: int, run_cem: bool) -> List[Prediction]:
    """CEMNet on ``pairs`` in batches (one untimed warm-up pair first); time per pair = batch time / batch size."""
    registrar.register_batch(_stack(pairs[:1], "source"), _stack(pairs[:1], "target"), run_cem=run_cem)
    out: List[Prediction] = []
    with tqdm(total=len(pairs), desc="cemnet", unit="pair", file=sys.stderr) as bar:
        for start in range(0, len(pairs), batch_size):
            batch = pairs[start:start + batch_size]
            began = time.perf_counter()
            result = registrar.register_batch(_stack(batch, "source"), _stack(batch, "target"), run_cem=run_cem)
            out += _batch_predictions(result, (time.perf_counter() - began) / len(batch))
            bar.update(len(batch))
    return out


def run_baseline(name: str, pairs: Sequence[RegistrationPair]) -> List[Prediction]:
    """The classical baseline ``name`` (``icp`` or ``fpfh``) on each pair."""
    solve = BASELINES[name]
    out = []
    for pair in tqdm(pairs, desc=name, unit="pair", file=sys.stderr):
        began = time.perf_counter()
        rotation, translation = solve(pair.source, pair.target)
        out.append(Prediction(rotation, translation, time.perf_counter() - began))
    return out
