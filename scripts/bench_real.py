#!/usr/bin/env python3
"""Real-data benchmark: real posed sequences through the node's pipeline, KISS-ICP and small_gicp in one run.

Sequences (each optional; the script downloads nothing):

* ``--balm DIR``: BALM's real-world benchmark, 177 handheld 360 deg scans 0.5 s apart (~73k points each) with
  a pose per scan. Get it with ``git clone https://github.com/hku-mars/BALM`` (commit 5dc1bf9); DIR is its
  ``datas/benchmark_realworld`` folder (``full0.pcd`` ... and ``alidarPose.csv``). Its licence is BALM's:
  keep it out of this repository.
* ``--kitti DIR``: the 6 KITTI sample scans (default: ``../shared/data/kitti_sample`` when present).

Per sequence and method: ATE (first poses aligned), end drift, worst step, steps off by > 10 cm or 1 deg
(accepted and flagged apart), the share of steps that ran the global search, and p50 / p95 ms per scan against
the sensor period. Prints a table, writes the JSON atomically.

    python scripts/bench_real.py --balm ~/BALM/datas/benchmark_realworld --out results/bench_real.json
    python scripts/bench_real.py --methods cemnet --balm DIR --limit 40 --set recovery.radius=5
    python scripts/bench_real.py --balm DIR --keyframes 2 5000   # also every 2nd scan thinned to 5000 points
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Optional

import yaml

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # runnable from a fresh checkout without `pip install`
    sys.path.insert(0, str(REPO))

from benchmarks.odometry import METHODS, available_methods  # noqa: E402
from benchmarks.real import balm_sequence, kitti_sequence, real_table, run_sequences  # noqa: E402
from benchmarks.streams import warm_up  # noqa: E402
from cemnet_ros.io.atomic import json_text, write_report  # noqa: E402
from cemnet_ros.pipeline.config import AlignerConfig  # noqa: E402
from cemnet_ros.schema import build  # noqa: E402
from cemnet_ros.tools.cli_errors import reported_errors  # noqa: E402

PROG = "bench_real.py"
SHARED_KITTI = REPO.parent / "shared" / "data" / "kitti_sample"


def parse_args(argv: Optional[list[str]]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--balm", type=Path, help="BALM's datas/benchmark_realworld folder")
    parser.add_argument("--kitti", type=Path, default=SHARED_KITTI if SHARED_KITTI.is_dir() else None,
                        help="KITTI sample folder (velodyne/, poses.txt, calib.txt)")
    parser.add_argument("--limit", type=int, help="first N scans of each sequence only")
    parser.add_argument("--keyframes", nargs=2, type=int, metavar=("STRIDE", "POINTS"),
                        help="also BALM as sparse keyframes: every STRIDE-th scan thinned to POINTS random points "
                             "(a stand-in for a solid-state keyframe stream)")
    parser.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS))
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                        help="node parameters for the pipeline under test (dotted names)")
    parser.add_argument("--out", type=Path, default=REPO / "results" / "bench_real.json")
    args = parser.parse_args(argv)
    if args.balm is None and args.kitti is None:
        parser.error("no sequence: give --balm DIR and/or --kitti DIR")
    overrides = {}
    for item in args.set:
        key, sep, value = item.partition("=")
        if not sep:
            parser.error(f"--set takes KEY=VALUE, not {item!r}")
        overrides[key] = yaml.safe_load(value)
    build(AlignerConfig(), overrides)  # an unknown or invalid parameter is a usage error now, not mid-run
    args.overrides = overrides
    return args


def main(argv: Optional[list[str]] = None) -> int:
    with reported_errors(PROG) as outcome:
        args = parse_args(argv)
        sequences = []
        if args.kitti is not None:
            kitti = kitti_sequence(args.kitti)
            sequences.append(kitti.first(args.limit) if args.limit else kitti)
        if args.balm is not None:
            sequences.append(balm_sequence(args.balm, args.limit))
            if args.keyframes:
                sequences.append(sequences[-1].keyframes(*args.keyframes))
        methods = available_methods(args.methods, args.overrides)
        warm_up(methods)
        results = run_sequences(sequences, methods)
        print(real_table(results))
        write_report(args.out, json_text({"overrides": args.overrides, "results": results}))
        print(f"wrote {args.out}")
    return outcome.code


if __name__ == "__main__":
    raise SystemExit(main())
