#!/usr/bin/env python3
"""Real-data benchmark: the development corpus through the node's pipeline, KISS-ICP, GenZ-ICP and small_gicp in
one run, with the judge measured as a classifier.

The corpus (each part optional; the script downloads nothing):

* ``--real-sets DIR``: the four sequences of ``../shared/real_sets`` (the folder ``real_sets.py extract`` wrote:
  BALM, Livox keyframes ``hku``, car keyframes ``riverside``, the 10 Hz handheld ``quick_shack``; their licences
  are not ours: keep them out of this repository), their stand-ins (``--stand-ins NAME:STRIDE:POINTS``, each
  drawn with every ``--seeds``; POINTS 0 keeps every point) and far pairs from no history (``--pairs N`` per set,
  10-40 m apart, through pair mode);
* ``--kitti DIR``: the 6 KITTI sample scans (default ``../shared/data/kitti_sample`` when present) and their
  keyframe stand-ins (every 2nd and 3rd scan thinned to 1/8 and 1/64).

Per sequence and method: ATE, end drift, the judge's confusion counts (accepted right / wrong, flagged right /
wrong: ``benchmarks/adjudication.py``) and the share of right steps accepted, the share of steps that ran the
global search, and p50 / p95 ms per scan against the sensor period; the far pairs' counts apart. Prints the tables,
writes the JSON atomically.

    python scripts/bench_real.py --real-sets DATA --out results/bench_real.json
    python scripts/bench_real.py --real-sets DATA --sets riverside --stand-ins riverside:2:0 --seeds 0 --pairs 0
    python scripts/bench_real.py --real-sets DATA --methods cemnet --set health.tie_ratio=0.9
    python scripts/bench_real.py --real-sets DATA --methods cemnet --scan-budget 1 --pairs 0
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

from benchmarks.far_pairs import far_pairs, run_far_pairs  # noqa: E402
from benchmarks.odometry import METHODS, available_methods  # noqa: E402
from benchmarks.real import REAL_SETS, kitti_sequence, real_set, real_table, run_sequences  # noqa: E402
from benchmarks.streams import warm_up  # noqa: E402
from cemnet_ros.io.atomic import json_text, write_report  # noqa: E402
from cemnet_ros.pipeline.config import AlignerConfig  # noqa: E402
from cemnet_ros.schema import build  # noqa: E402
from cemnet_ros.tools.cli_errors import reported_errors  # noqa: E402

PROG = "bench_real.py"
SHARED_KITTI = REPO.parent / "shared" / "data" / "kitti_sample"
STAND_INS = ("balm:2:5000", "balm:3:5000", "hku:2:2500", "riverside:2:6500", "quick_shack:2:2500")
KITTI_STAND_INS = ((2, 8), (2, 64), (3, 8), (3, 64))  # (stride, thinning) of the KITTI keyframes


def parse_args(argv: Optional[list[str]]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--real-sets", type=Path, help="the folder ../shared/real_sets/real_sets.py extracted into")
    parser.add_argument("--sets", nargs="*", choices=REAL_SETS, default=list(REAL_SETS),
                        help="which of the four real sequences run whole (default: all)")
    parser.add_argument("--stand-ins", nargs="*", default=list(STAND_INS), metavar="NAME:STRIDE:POINTS",
                        help="stand-ins: every STRIDE-th scan of a real set thinned to POINTS (0: all), one per seed")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3], help="the stand-ins' thinning seeds")
    parser.add_argument("--pairs", type=int, default=20, help="far pairs (10-40 m, from no history) per real set")
    parser.add_argument("--kitti", type=Path, default=SHARED_KITTI if SHARED_KITTI.is_dir() else None,
                        help="KITTI sample folder (velodyne/, poses.txt, calib.txt)")
    parser.add_argument("--no-kitti", action="store_true", help="leave the KITTI scans out")
    parser.add_argument("--limit", type=int, help="first N scans of each sequence only")
    parser.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS))
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                        help="node parameters for the pipeline under test (dotted names)")
    parser.add_argument("--scan-budget", type=float, default=0.0, metavar="PERIODS",
                        help="the pipeline under test bounds each scan as a live node's scan_budget does (every scan "
                             "still processed: what the budget alone changes); default 0: none, as offline")
    parser.add_argument("--out", type=Path, default=REPO / "results" / "bench_real.json")
    args = parser.parse_args(argv)
    if args.no_kitti:
        args.kitti = None
    if args.real_sets is None and args.kitti is None:
        parser.error("no sequence: give --real-sets DIR and/or --kitti DIR")
    overrides = {}
    for item in args.set:
        key, sep, value = item.partition("=")
        if not sep:
            parser.error(f"--set takes KEY=VALUE, not {item!r}")
        overrides[key] = yaml.safe_load(value)
    build(AlignerConfig(), overrides)  # an unknown or invalid parameter is a usage error now, not mid-run
    args.overrides = overrides
    for spec in args.stand_ins:
        name, *numbers = spec.split(":")
        if name not in REAL_SETS or len(numbers) != 2 or not all(n.isdigit() for n in numbers):
            parser.error(f"--stand-ins takes NAME:STRIDE:POINTS with NAME one of {REAL_SETS}, not {spec!r}")
    return args


def corpus(args: argparse.Namespace) -> tuple[list, dict]:
    """The sequences to run, and the real sets by name (the far pairs' source)."""
    sequences, real = [], {}
    if args.kitti is not None:
        kitti = kitti_sequence(args.kitti)
        points = len(kitti.scans[0])
        sequences.append(kitti)
        sequences += [kitti.keyframes(stride, points // thinning, seed)
                      for stride, thinning in KITTI_STAND_INS for seed in args.seeds]
    if args.real_sets is not None:
        wanted = set(args.sets) | {spec.split(":")[0] for spec in args.stand_ins}
        real = {name: real_set(args.real_sets, name) for name in REAL_SETS if name in wanted}
        sequences += [real[name] for name in args.sets]
        for spec in args.stand_ins:
            name, stride, points = spec.split(":")
            seeds = args.seeds if int(points) else args.seeds[:1]
            sequences += [real[name].keyframes(int(stride), int(points), seed) for seed in seeds]
    if args.limit:
        sequences = [s.first(args.limit) for s in sequences]
    return sequences, real


def pairs_table(results: dict) -> str:
    """A markdown table of the far pairs: one row per set and method."""
    rows = ["| far pairs | method | accepted right | accepted wrong | flagged right | flagged wrong | ms p50 |",
            "|---|---|---|---|---|---|---|"]
    for name, methods in results.items():
        for method, m in methods.items():
            ms = "-" if m["ms_p50"] is None else f"{m['ms_p50']:.0f}"
            rows.append(f"| {name} | {method} | {m['accepted_right']} | {m['accepted_wrong']} | {m['flagged_right']} "
                        f"| {m['flagged_wrong']} | {ms} |")
    return "\n".join(rows)


def main(argv: Optional[list[str]] = None) -> int:
    with reported_errors(PROG) as outcome:
        args = parse_args(argv)
        sequences, real = corpus(args)
        methods = available_methods(args.methods, args.overrides, args.scan_budget)
        warm_up(methods)
        report: dict = {"overrides": args.overrides, "scan_budget": args.scan_budget, "results": {}, "far_pairs": {}}
        for sequence in sequences:
            report["results"].update(run_sequences([sequence], methods))
            write_report(args.out, json_text(report))  # a long run keeps what it measured
        for name, sequence in real.items():
            pairs = far_pairs(sequence, args.pairs, seed=0) if args.pairs else []
            if pairs:
                report["far_pairs"][name] = run_far_pairs(sequence, pairs, methods)
                write_report(args.out, json_text(report))
        print(real_table(report["results"]))
        if report["far_pairs"]:
            print()
            print(pairs_table(report["far_pairs"]))
        print(f"wrote {args.out}")
    return outcome.code


if __name__ == "__main__":
    raise SystemExit(main())
