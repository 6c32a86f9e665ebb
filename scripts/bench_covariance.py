#!/usr/bin/env python3
"""Covariance benchmark: is the node's published pose covariance consistent with its real errors?

Per sequence and ``covariance_mode`` (registration, fixed): the NEES of every step's error against ground
truth (mean, expected 6; the share of steps below the 95 % chi-square bound 12.59; the translation and rotation
blocks, expected 3 each), and the ATE of the odometry before and after a pose graph closes it with the true
first-to-last motion (``benchmarks/covariance_runs.py``). Sequences (the script downloads nothing):

* ``--balm DIR``: BALM's ``datas/benchmark_realworld`` (hku-mars/BALM, its licence: keep it out of this repo);
* ``--bag PATH [PATH ...]``: bags with ground truth (default ``bags/kitti_00_6scans.mcap``; ``--bag none``: no
  bag).

    python scripts/bench_covariance.py --balm ~/BALM/datas/benchmark_realworld --out results/bench_covariance.json
    python scripts/bench_covariance.py --bag bags/synthetic_lidar.mcap bags/rgbd_7scenes_50.mcap
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Optional

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # runnable from a fresh checkout without `pip install`
    sys.path.insert(0, str(REPO))

from benchmarks.covariance_runs import evaluate, nees_table, rms_lines  # noqa: E402
from benchmarks.live import bag_sequence  # noqa: E402
from benchmarks.real import Sequence, balm_sequence  # noqa: E402
from cemnet_ros.io.atomic import json_text, write_report  # noqa: E402
from cemnet_ros.tools.cli_errors import reported_errors  # noqa: E402

PROG = "bench_covariance.py"
KITTI_BAG = REPO / "bags" / "kitti_00_6scans.mcap"


def parse_args(argv: Optional[list[str]]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--balm", type=Path, help="BALM's datas/benchmark_realworld folder")
    parser.add_argument("--bag", nargs="+", default=[str(KITTI_BAG)], help="bags with ground truth ('none': no bag)")
    parser.add_argument("--limit", type=int, help="first N scans of each sequence only")
    parser.add_argument("--out", type=Path, default=REPO / "results" / "bench_covariance.json")
    args = parser.parse_args(argv)
    args.bag = [] if args.bag == ["none"] else [Path(bag) for bag in args.bag]
    if args.balm is None and not args.bag:
        parser.error("no sequence: give --balm DIR and/or --bag PATH")
    return args


def sequences(args: argparse.Namespace) -> list[Sequence]:
    """The bags' scans (the first ``--limit``) and BALM's, as asked."""
    bags = [bag_sequence(path) for path in args.bag]
    balm = [] if args.balm is None else [balm_sequence(args.balm, args.limit)]
    return [s.first(args.limit) if args.limit else s for s in bags] + balm


def main(argv: Optional[list[str]] = None) -> int:
    with reported_errors(PROG) as outcome:
        args = parse_args(argv)
        results = {seq.name: evaluate(seq) for seq in sequences(args)}
        print(nees_table(results), rms_lines(results), sep="\n")
        print(f"wrote {write_report(args.out, json_text({'results': results}))}")
    return outcome.code


if __name__ == "__main__":
    raise SystemExit(main())
