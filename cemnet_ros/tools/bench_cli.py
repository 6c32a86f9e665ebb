"""cemnet-bench: per-pair latency of ``Registrar.register`` (paper settings) and of plain ICP, same pairs.

Pairs are 768-point partial pairs made by the evaluation protocol from ``--data`` (test split) or, without
data, from a built-in synthetic shape. Both methods are warmed up first (numba JIT, torch allocations),
then timed pair by pair with a wall clock; prints median and p90 latency and the CEMNet/ICP ratio.
"""
from __future__ import annotations

import argparse
import platform
import sys
import time
from dataclasses import asdict, dataclass, field
from typing import Any, List, Optional, Sequence

import numpy as np
import torch
from tqdm import tqdm

from cemnet_ros.core import Registrar
from cemnet_ros.core.checkpoint import CheckpointError
from cemnet_ros.core.config import RegistrationConfig
from cemnet_ros.data.shapes import bracket_shape
from cemnet_ros.eval.baselines import icp
from cemnet_ros.eval.metrics import pair_metrics
from cemnet_ros.eval.protocol import ProtocolConfig, RegistrationPair, load_shapes, make_pair
from cemnet_ros.io.report import Report, emit
from cemnet_ros.tools.cli_errors import reported_errors
from cemnet_ros.tools.engine_args import add_engine_args, config_from_args

PROG = "cemnet-bench"
METHODS = ("cemnet", "icp")


@dataclass(frozen=True)
class BenchConfig:
    """What to time: ``pairs`` protocol pairs from ``data`` (None: a synthetic shape), after ``warmup`` calls."""

    data: Optional[str] = None
    pairs: int = 20
    warmup: int = 2
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)

    def __post_init__(self) -> None:
        if self.pairs < 1 or self.warmup < 0:
            raise ValueError("--pairs must be >= 1 and --warmup >= 0")


@dataclass
class BenchReport(Report):
    """Per-pair wall times (s) and rotation errors (deg) of each method, and the machine's thread counts."""

    config: BenchConfig
    n_points: int
    seconds: dict[str, list[float]]
    rot_err_deg: dict[str, list[float]]
    threads: dict[str, Optional[int]]

    def stats(self) -> dict[str, dict[str, float]]:
        out = {}
        for name, seconds in self.seconds.items():
            ms = np.asarray(seconds) * 1e3
            out[name] = {"median_ms": float(np.median(ms)), "p90_ms": float(np.percentile(ms, 90)),
                         "mean_ms": float(ms.mean()), "min_ms": float(ms.min()),
                         "median_rot_err_deg": float(np.median(self.rot_err_deg[name]))}
        return out

    def ratio(self) -> float:
        """CEMNet's median latency over ICP's."""
        return float(np.median(self.seconds["cemnet"]) / np.median(self.seconds["icp"]))

    def to_markdown(self) -> str:
        cfg, cem, threads = self.config, self.config.registration.cem, self.threads
        source = f"data {cfg.data}" if cfg.data else "synthetic shape"
        lines = [f"{cfg.pairs} pairs of {self.n_points} points ({source});"
                 f" CEM N={cem.n_candidates} T={cem.n_iters} M={cem.n_fused_iters}, prior={cfg.registration.prior};"
                 f" threads: torch {threads['torch']} (interop {threads['torch_interop']}), numba {threads['numba']}",
                 "| method | median ms | p90 ms | median rot err deg |", "|---|---:|---:|---:|"]
        lines += [f"| {name} | {s['median_ms']:.1f} | {s['p90_ms']:.1f} | {s['median_rot_err_deg']:.3f} |"
                  for name, s in self.stats().items()]
        return "\n".join(lines + [f"CEMNet / ICP median latency ratio: {self.ratio():.1f}"])

    def as_dict(self) -> dict[str, Any]:
        return {"config": {**asdict(self.config), "n_points": self.n_points, "python": platform.python_version(),
                           "torch": torch.__version__, "threads": self.threads},
                "stats": self.stats(), "ratio_median": self.ratio(),
                "per_pair_ms": {name: [s * 1e3 for s in t] for name, t in self.seconds.items()}}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default=None, help="shape archive .npz; default: a synthetic shape")
    parser.add_argument("--pairs", type=int, default=20, help="timed pairs (default: 20)")
    parser.add_argument("--warmup", type=int, default=2, help="untimed warm-up registrations (default: 2)")
    parser.add_argument("--json", default=None, help="write the figures (and per-pair times) here")
    add_engine_args(parser)
    return parser


def make_pairs(data: Optional[str], n_pairs: int) -> List[RegistrationPair]:
    """``n_pairs`` protocol pairs (pair i seeded with i) from the test shapes of ``data`` or a synthetic shape."""
    cfg = ProtocolConfig()
    if data is None:
        shapes = bracket_shape(cfg.n_points)[None]
    else:
        shapes, _ = load_shapes(data, "test")
        if len(shapes) == 0:
            raise ValueError(f"{data}: no test shapes")
    return [make_pair(shapes[i % len(shapes)], np.random.default_rng(i), cfg) for i in range(n_pairs)]


def _numba_threads() -> Optional[int]:
    try:
        import numba
    except ImportError:
        return None
    return int(numba.get_num_threads())


def _threads() -> dict[str, Optional[int]]:
    return {"torch": torch.get_num_threads(), "torch_interop": torch.get_num_interop_threads(),
            "numba": _numba_threads()}


def run(config: BenchConfig) -> BenchReport:
    """Warm both methods up on the first pair, then time them pair by pair."""
    pairs = make_pairs(config.data, config.pairs)
    registrar = Registrar(config.registration)
    for _ in range(config.warmup):
        registrar.register(pairs[0].source, pairs[0].target)
        icp(pairs[0].source, pairs[0].target)
    seconds: dict[str, list[float]] = {name: [] for name in METHODS}
    rot_err: dict[str, list[float]] = {name: [] for name in METHODS}
    for pair in tqdm(pairs, desc="bench", unit="pair", file=sys.stderr):
        began = time.perf_counter()
        res = registrar.register(pair.source, pair.target)
        seconds["cemnet"].append(time.perf_counter() - began)
        began = time.perf_counter()
        rotation, translation = icp(pair.source, pair.target)
        seconds["icp"].append(time.perf_counter() - began)
        for name, (r, t) in (("cemnet", (res.rotation, res.translation)), ("icp", (rotation, translation))):
            rot_err[name].append(pair_metrics(r, t, pair.rotation, pair.translation).rot_err_deg)
    return BenchReport(config, len(pairs[0].source), seconds, rot_err, _threads())


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = build_parser().parse_args(argv)
    with reported_errors(PROG, CheckpointError) as outcome:
        config = BenchConfig(args.data, args.pairs, args.warmup, config_from_args(args))
        emit(run(config), args.json)
    return outcome.code


if __name__ == "__main__":
    sys.exit(main())
