"""cemnet-eval: CEMNet and classical baselines on the paper's ModelNet40 protocol, with the same pairs.

Example::

    cemnet-eval --data modelnet40_subset.npz --setting noisy \\
        --weights modelnet40_n768_unseen0_noise1_seed123.pth --allow-pickle --out-json noisy.json

Prints a markdown table (one row per method) and optionally writes JSON (config, per-pair metrics,
aggregates) and the markdown table to files, atomically.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import sys
import time
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np
import torch
from tqdm import tqdm

from cemnet_ros.core import Registrar
from cemnet_ros.core.checkpoint import CheckpointError
from cemnet_ros.eval.baselines import fpfh_ransac, icp, open3d_available
from cemnet_ros.eval.metrics import aggregate, pair_metrics
from cemnet_ros.eval.protocol import FAR_POINTS, ProtocolConfig, RegistrationPair, load_shapes, protocol_pairs
from cemnet_ros.io.atomic import atomic_write_text
from cemnet_ros.tools.engine_args import add_engine_args, config_from_args

METHODS = ("cemnet", "icp", "fpfh")
SETTINGS = ("clean", "noisy", "unseen")
PROG = "cemnet-eval"

# (header, aggregate key, format)
_COLUMNS = (
    ("MAE(R) deg", "r_mae_deg", "{:.4f}"), ("RMSE(R) deg", "r_rmse_deg", "{:.4f}"),
    ("MAE(t)", "t_mae", "{:.6f}"), ("RMSE(t)", "t_rmse", "{:.6f}"),
    ("iso R err deg (mean)", "rot_err_deg_mean", "{:.4f}"), ("iso t err (mean)", "trans_err_mean", "{:.6f}"),
    ("recall", "recall", "{:.3f}"), ("median ms/pair", "median_ms_per_pair", "{:.1f}"),
)


class _Prediction:
    """One method's answer for one pair."""

    __slots__ = ("rotation", "translation", "seconds", "extra")

    def __init__(self, rotation: np.ndarray, translation: np.ndarray, seconds: float, extra: Optional[dict] = None):
        self.rotation, self.translation, self.seconds, self.extra = rotation, translation, seconds, extra or {}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", required=True, help="shape archive .npz (points (S,n,3), labels, split)")
    parser.add_argument("--split", choices=("train", "test", "all"), default="test", help="default: test")
    parser.add_argument("--setting", choices=SETTINGS, default="clean",
                        help="clean; noisy: N(0, 0.01) clipped to 0.05 on both clouds; unseen: test on "
                             "categories with label >= 20 (default: clean)")
    parser.add_argument("--full", action="store_true", help="no partial crop (default: 768-point partial views)")
    parser.add_argument("--far-point", choices=FAR_POINTS, default="reference",
                        help="partial crop point: the reference's +-500 (1,1,1) diagonal (default), "
                             "or a random direction")
    parser.add_argument("--methods", default=None,
                        help=f"comma-separated subset of {','.join(METHODS)} "
                             "(default: cemnet,icp, plus fpfh when Open3D is importable)")
    parser.add_argument("--mode", choices=("cem", "network"), default="cem",
                        help="cem: the full method; network: the sampling network's mu0 alone (ablation); default: cem")
    parser.add_argument("--batch-size", type=int, default=8,
                        help="pairs per Registrar.register_batch call (default: 8)")
    parser.add_argument("--limit", type=int, default=None, help="evaluate only the first N shapes")
    parser.add_argument("--seed-offset", type=int, default=0, help="pair i is drawn with seed offset + i (default: 0)")
    parser.add_argument("--out-json", default=None, help="write config, per-pair metrics and aggregates here")
    parser.add_argument("--out-md", default=None, help="write the markdown table here")
    add_engine_args(parser)
    return parser


def _parse_methods(text: Optional[str]) -> List[str]:
    if text is None:
        return ["cemnet", "icp"] + (["fpfh"] if open3d_available() else [])
    methods = [m.strip().lower() for m in text.split(",") if m.strip()]
    unknown = sorted(set(methods) - set(METHODS))
    if unknown or not methods:
        raise ValueError(f"--methods: unknown {unknown or 'empty list'}; choose from {', '.join(METHODS)}")
    return list(dict.fromkeys(methods))


def _run_cemnet(registrar: Registrar, pairs: Sequence[RegistrationPair], batch_size: int, run_cem: bool
                ) -> List[_Prediction]:
    stack = lambda items, field: torch.from_numpy(np.stack([getattr(p, field) for p in items]))  # noqa: E731
    registrar.register_batch(stack(pairs[:1], "source"), stack(pairs[:1], "target"), run_cem=run_cem)  # warm-up
    out: List[_Prediction] = []
    with tqdm(total=len(pairs), desc="cemnet", unit="pair", file=sys.stderr) as bar:
        for start in range(0, len(pairs), batch_size):
            batch = pairs[start:start + batch_size]
            began = time.perf_counter()
            res = registrar.register_batch(stack(batch, "source"), stack(batch, "target"), run_cem=run_cem)
            per_pair = (time.perf_counter() - began) / len(batch)
            for b in range(len(batch)):
                extra = {"fitness": float(res.fitness[b]), "sigma": res.sigma[b].tolist(), "mu0": res.mu0[b].tolist()}
                out.append(_Prediction(res.rotation[b], res.translation[b], per_pair, extra))
            bar.update(len(batch))
    return out


def _run_baseline(name: str, solve: Callable, pairs: Sequence[RegistrationPair]) -> List[_Prediction]:
    out = []
    for pair in tqdm(pairs, desc=name, unit="pair", file=sys.stderr):
        began = time.perf_counter()
        rotation, translation = solve(pair.source, pair.target)
        out.append(_Prediction(rotation, translation, time.perf_counter() - began))
    return out


def markdown_table(aggregates: Dict[str, Dict[str, float]], title: str) -> str:
    """Markdown table, one row per method."""
    lines = [f"### {title}", "", "| method | " + " | ".join(c[0] for c in _COLUMNS) + " |",
             "|---|" + "---:|" * len(_COLUMNS)]
    for method, agg in aggregates.items():
        lines.append(f"| {method} | " + " | ".join(fmt.format(agg[key]) for _, key, fmt in _COLUMNS) + " |")
    return "\n".join(lines) + "\n"


def _write(path: str, text: str) -> None:
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(target, text)


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if args.batch_size < 1 or (args.limit is not None and args.limit < 1):
            raise ValueError("--batch-size and --limit must be >= 1")
        methods = _parse_methods(args.methods)
        if "fpfh" in methods and not open3d_available():
            print(f"{PROG}: skipping fpfh: Open3D cannot be imported (pip install open3d-cpu; Debian also needs "
                  "apt-get install libusb-1.0-0)", file=sys.stderr)
            methods.remove("fpfh")
            if not methods:
                raise ValueError("no method left to evaluate")
        protocol = ProtocolConfig(partial=not args.full, noise=args.setting == "noisy", far_point=args.far_point)
        points, labels = load_shapes(args.data, args.split, unseen=args.setting == "unseen")
        points = points[:args.limit]
        if len(points) == 0:
            raise ValueError(f"{args.data}: no shapes in split {args.split!r} for setting {args.setting!r}")
        pairs = list(protocol_pairs(points, protocol, args.seed_offset))
        config = config_from_args(args)
        registrar = Registrar(config) if "cemnet" in methods else None
    except (FileNotFoundError, ValueError, CheckpointError) as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2

    predictions: Dict[str, List[_Prediction]] = {}
    for method in methods:
        if method == "cemnet":
            predictions[method] = _run_cemnet(registrar, pairs, args.batch_size, run_cem=args.mode == "cem")
        else:
            predictions[method] = _run_baseline(method, icp if method == "icp" else fpfh_ransac, pairs)

    per_pair: Dict[str, list] = {}
    aggregates: Dict[str, Dict[str, float]] = {}
    for method, preds in predictions.items():
        metrics = [pair_metrics(p.rotation, p.translation, pair.rotation, pair.translation)
                   for p, pair in zip(preds, pairs)]
        aggregates[method] = aggregate(metrics)
        aggregates[method]["median_ms_per_pair"] = float(np.median([p.seconds for p in preds]) * 1e3)
        per_pair[method] = [
            {"pair": i, "label": None if labels is None else int(labels[i]), **m.as_dict(),
             "time_ms": p.seconds * 1e3, "rotation": p.rotation.tolist(), "translation": p.translation.tolist(),
             **p.extra}
            for i, (m, p) in enumerate(zip(metrics, preds))]

    name = {"cemnet": "cemnet" if args.mode == "cem" else "cemnet (network only)"}
    shown = {name.get(m, m): agg for m, agg in aggregates.items()}
    crop = "full" if args.full else f"partial ({args.far_point} far point)"
    title = (f"{args.setting}, {crop}, split {args.split}, {len(pairs)} pairs"
             f" (weights: {Path(config.weights).name if config.weights else 'package default'})")
    table = markdown_table(shown, title)
    print(table)
    try:
        if args.out_md:
            _write(args.out_md, table)
        if args.out_json:
            report = {
                "config": {"args": vars(args), "protocol": dataclasses.asdict(protocol),
                           "registration": dataclasses.asdict(config), "methods": methods,
                           "python": platform.python_version(), "torch": torch.__version__,
                           "torch_threads": torch.get_num_threads()},
                "aggregates": aggregates,
                "per_pair": per_pair,
            }
            _write(args.out_json, json.dumps(report, indent=1) + "\n")
    except OSError as exc:
        print(f"{PROG}: error: cannot write output: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
