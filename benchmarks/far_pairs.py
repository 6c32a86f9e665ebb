"""Far scan pairs from no history: pair mode (``align_clouds``, ``cemnet-register``) where it is hardest.

Pairs of scans of one real sequence whose sensor positions lie ``min_m`` to ``max_m`` apart (10-40 m: a car's
keyframes a few seconds apart, a handheld walk around a corner), drawn with a seed, each registered from nothing:
the node through its pair mode (:meth:`~cemnet_ros.pipeline.aligner.ScanAligner.align_pair`, what
:func:`cemnet_ros.align_clouds.align_clouds` and ``cemnet-register`` run; judged), the peers
as the first two scans of a fresh odometry (small_gicp GICP from the identity, KISS-ICP, GenZ-ICP; they accept
every pair). An answer is right as in :mod:`.adjudication`: within the sequence's thresholds of the reference or
of GICP's optimum started from it (the pairs the two scans cannot register right are the ones to flag).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from benchmarks.adjudication import DataOptimum, Judged, answer_is_right, confusion
from benchmarks.real import Sequence
from cemnet_ros.io.console import progress


@dataclass(frozen=True)
class FarPair:
    """Scan ``source`` of a sequence registered onto its scan ``target``."""

    target: int
    source: int
    metres: float  # how far apart the two sensor positions are


def far_pairs(sequence: Sequence, n: int, seed: int, min_m: float = 10.0, max_m: float = 40.0) -> list[FarPair]:
    """``n`` pairs (fewer if the sequence has fewer) whose positions lie ``min_m`` to ``max_m`` apart, drawn
    uniformly over the distance range (so that 30 m pairs are not crowded out by the many 10 m ones)."""
    positions = np.array([pose[:3, 3] for pose in sequence.poses])
    distance = np.linalg.norm(positions[:, None] - positions[None], axis=2)
    targets, sources = np.nonzero(np.triu((distance >= min_m) & (distance <= max_m), 1))
    if not len(targets):
        return []
    rng = np.random.default_rng(seed)
    wanted = rng.uniform(min_m, max_m, size=min(n, len(targets)))
    chosen: list[int] = []
    for metres in wanted:
        order = np.argsort(np.abs(distance[targets, sources] - metres))
        chosen.append(next(int(i) for i in order if int(i) not in chosen))
    return [FarPair(int(targets[i]), int(sources[i]), float(distance[targets[i], sources[i]])) for i in chosen]


def run_far_pairs(sequence: Sequence, pairs: list[FarPair], methods: dict[str, Callable]) -> dict:
    """Every pair through every method: {method: {confusion counts, ms, pairs: [...]}}."""
    optimum = DataOptimum(sequence.scans)
    out = {}
    for name, factory in methods.items():
        records, judged = [], []
        for pair in progress(pairs, desc=f"{sequence.name} far pairs: {name}"):
            start = time.perf_counter()
            T_answer, accepted, reason = _register(name, factory, sequence, pair)
            ms = 1e3 * (time.perf_counter() - start)
            right, metres, degrees = answer_is_right(np.eye(4), T_answer, sequence.poses[pair.target],
                                                     sequence.poses[pair.source], sequence.off, optimum,
                                                     pair.target, pair.source)
            judged.append(Judged(pair.source, pair.target, accepted, right, metres, degrees))
            records.append({"target": pair.target, "source": pair.source, "apart_m": round(pair.metres, 1),
                            "accepted": accepted, "right": right, "error_m": round(metres, 3),
                            "error_deg": round(degrees, 2), "ms": round(ms, 1), "reason": reason})
        out[name] = {**confusion(judged), "ms_p50": float(np.median([r["ms"] for r in records])) if records else None,
                     "pairs": records}
    return out


def _register(name: str, factory: Callable, sequence: Sequence, pair: FarPair) -> tuple[np.ndarray | None, bool, str]:
    """(T_target_source or None, accepted, reason) of one method on one pair."""
    source, target = sequence.scans[pair.source], sequence.scans[pair.target]
    try:
        odometry = factory(sequence.max_range)
        if name == "cemnet":
            result = odometry.pair(source, target)
            return result.pose, result.accepted, result.reason
        odometry.process(target, 0)
        return np.asarray(odometry.process(source, 100_000_000).pose), True, ""
    except Exception as exc:  # noqa: BLE001 - the benchmark counts every failure
        return None, False, repr(exc)
