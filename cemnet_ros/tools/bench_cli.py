"""cemnet-bench: per-pair latency of ``Registrar.register`` (paper settings) and of plain ICP, same pairs.

Pairs are 768-point partial pairs made by the evaluation protocol from ``--data`` (test split) or, without
data, from a built-in synthetic shape. Both methods are warmed up first (numba JIT, torch allocations),
then timed pair by pair with a wall clock; prints median and p90 latency and the CEMNet/ICP ratio.
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path
from typing import List, Optional, Sequence

import numpy as np
import torch
from tqdm import tqdm

from cemnet_ros.core import Registrar
from cemnet_ros.core.checkpoint import CheckpointError
from cemnet_ros.data.shapes import bracket_shape
from cemnet_ros.eval.baselines import icp
from cemnet_ros.eval.metrics import pair_metrics
from cemnet_ros.eval.protocol import ProtocolConfig, RegistrationPair, load_shapes, make_pair
from cemnet_ros.io.atomic import atomic_write_text
from cemnet_ros.tools.engine_args import add_engine_args, config_from_args

PROG = "cemnet-bench"


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


def _stats(seconds: Sequence[float]) -> dict:
    ms = np.asarray(seconds) * 1e3
    return {"median_ms": float(np.median(ms)), "p90_ms": float(np.percentile(ms, 90)),
            "mean_ms": float(ms.mean()), "min_ms": float(ms.min())}


def _numba_threads() -> Optional[int]:
    try:
        import numba
    except ImportError:
        return None
    return int(numba.get_num_threads())


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if args.pairs < 1 or args.warmup < 0:
            raise ValueError("--pairs must be >= 1 and --warmup >= 0")
        pairs = make_pairs(args.data, args.pairs)
        config = config_from_args(args)
        registrar = Registrar(config)
    except (FileNotFoundError, ValueError, CheckpointError) as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2

    for _ in range(args.warmup):
        registrar.register(pairs[0].source, pairs[0].target)
        icp(pairs[0].source, pairs[0].target)
    times = {"cemnet": [], "icp": []}
    rot_err = {"cemnet": [], "icp": []}
    for pair in tqdm(pairs, desc="bench", unit="pair", file=sys.stderr):
        began = time.perf_counter()
        res = registrar.register(pair.source, pair.target)
        times["cemnet"].append(time.perf_counter() - began)
        began = time.perf_counter()
        rotation, translation = icp(pair.source, pair.target)
        times["icp"].append(time.perf_counter() - began)
        for name, (r, t) in (("cemnet", (res.rotation, res.translation)), ("icp", (rotation, translation))):
            rot_err[name].append(pair_metrics(r, t, pair.rotation, pair.translation).rot_err_deg)

    stats = {name: {**_stats(t), "median_rot_err_deg": float(np.median(rot_err[name]))} for name, t in times.items()}
    ratio = stats["cemnet"]["median_ms"] / stats["icp"]["median_ms"]
    threads = {"torch": torch.get_num_threads(), "torch_interop": torch.get_num_interop_threads(),
               "numba": _numba_threads()}
    cem = config.cem
    source = f"data {args.data}" if args.data else "synthetic shape"
    print(f"{len(pairs)} pairs of {len(pairs[0].source)} points ({source});"
          f" CEM N={cem.n_candidates} T={cem.n_iters} M={cem.n_fused_iters}, prior={config.prior};"
          f" threads: torch {threads['torch']} (interop {threads['torch_interop']}), numba {threads['numba']}")
    print("| method | median ms | p90 ms | median rot err deg |\n|---|---:|---:|---:|")
    for name, s in stats.items():
        print(f"| {name} | {s['median_ms']:.1f} | {s['p90_ms']:.1f} | {s['median_rot_err_deg']:.3f} |")
    print(f"CEMNet / ICP median latency ratio: {ratio:.1f}")
    if args.json:
        report = {"config": {"args": vars(args), "n_points": len(pairs[0].source), "python": platform.python_version(),
                             "torch": torch.__version__, "threads": threads},
                  "stats": stats, "ratio_median": ratio,
                  "per_pair_ms": {name: [s * 1e3 for s in t] for name, t in times.items()}}
        try:
            path = Path(args.json)
            path.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(path, json.dumps(report, indent=1) + "\n")
        except OSError as exc:
            print(f"{PROG}: error: cannot write {args.json}: {exc}", file=sys.stderr)
            return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
