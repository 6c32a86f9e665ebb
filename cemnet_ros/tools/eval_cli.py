"""cemnet-eval: CEMNet and classical baselines on the paper's ModelNet40 or 7-Scenes protocol, with the same pairs.

Examples::

    cemnet-eval --data modelnet40_subset.npz --setting noisy \\
        --weights modelnet40_n768_unseen0_noise1_seed123.pth --allow-pickle --out-json noisy.json
    cemnet-eval --source rgbd --data rgbd_7scenes \\
        --weights scene7_n768_unseen0_noise0_seed123.pth --allow-pickle --methods cemnet,icp,fpfh

Prints a markdown table (one row per method) and optionally writes JSON (config, per-pair metrics,
aggregates) and the markdown table to files, atomically. The work is :func:`cemnet_ros.eval.runner.run`.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Optional, Sequence, Tuple

from cemnet_ros.core.checkpoint import CheckpointError
from cemnet_ros.eval.baselines import open3d_available
from cemnet_ros.eval.protocol import FAR_POINTS
from cemnet_ros.eval.runner import METHODS, SETTINGS, SOURCES, EvalConfig, run
from cemnet_ros.eval.sevenscenes import SevenScenesConfig
from cemnet_ros.io.atomic import atomic_write_text
from cemnet_ros.schema import add_arguments, build, parameters, parsed_overrides
from cemnet_ros.tools.cli_errors import reported_errors
from cemnet_ros.tools.engine_args import add_engine_args, config_from_args

PROG = "cemnet-eval"
RGBD = parameters(SevenScenesConfig(), prefix="rgbd.")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", required=True, help="shape archive .npz (points (S,n,3), labels, split), or "
                        "with --source rgbd a 7-Scenes folder (camera-intrinsics.txt, rgbd-frames/)")
    parser.add_argument("--source", choices=SOURCES, default="shapes",
                        help="shapes: the ModelNet40 protocol on a shape archive; rgbd: the paper's 7Scene protocol "
                             "on depth frames (docs/evaluation.md; default: shapes)")
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
    parser.add_argument("--limit", type=int, default=None, help="evaluate only the first N clouds")
    parser.add_argument("--seed-offset", type=int, default=0, help="pair i is drawn with seed offset + i (default: 0)")
    parser.add_argument("--out-json", default=None, help="write config, per-pair metrics and aggregates here")
    parser.add_argument("--out-md", default=None, help="write the markdown table here")
    add_engine_args(parser)
    add_arguments(parser, RGBD, "7-Scenes clouds (--source rgbd)")
    return parser


def methods_from_text(text: Optional[str]) -> Tuple[str, ...]:
    """``--methods`` as a tuple; the default, and a requested fpfh without Open3D, say what they leave out."""
    if text is None:
        return ("cemnet", "icp") + (("fpfh",) if open3d_available() else ())
    methods = tuple(dict.fromkeys(m.strip().lower() for m in text.split(",") if m.strip()))
    if "fpfh" in methods and set(methods) <= set(METHODS) and not open3d_available():
        print(f"{PROG}: skipping fpfh: Open3D cannot be imported (pip install open3d-cpu; Debian also needs "
              "apt-get install libusb-1.0-0)", file=sys.stderr)
        methods = tuple(m for m in methods if m != "fpfh")
        if not methods:
            raise ValueError("no method left to evaluate")
    return methods


def config_from(args: argparse.Namespace) -> EvalConfig:
    """The run the flags describe (ValueError on a bad combination)."""
    rgbd = build(SevenScenesConfig(), {k[len("rgbd."):]: v for k, v in parsed_overrides(args, RGBD).items()})
    return EvalConfig(data=args.data, methods=methods_from_text(args.methods), source=args.source,
                      split=args.split, setting=args.setting, full=args.full, far_point=args.far_point,
                      mode=args.mode, batch_size=args.batch_size, limit=args.limit, seed_offset=args.seed_offset,
                      registration=config_from_args(args), rgbd=rgbd)


def _write(path: str, text: str) -> None:
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(target, text)


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = build_parser().parse_args(argv)
    with reported_errors(PROG, CheckpointError) as outcome:
        report = run(config_from(args))
        table = report.to_markdown()
        print(table)
        if args.out_md:
            _write(args.out_md, table)
        if args.out_json:
            _write(args.out_json, report.to_json())
    return outcome.code


if __name__ == "__main__":
    sys.exit(main())
