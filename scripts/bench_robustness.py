#!/usr/bin/env python3
"""Robustness benchmark of the odometry pipeline (``ScanAligner``) and of KISS-ICP / small_gicp peers.

Sets (``--sets``; seeds are fixed and printed):

* ``kitti_gaps``: the 6 full-resolution KITTI scans of ../shared, every pair (i, i+g), g = 1..``--max-gap``,
  as the first two scans of a fresh odometry (stamps 0 and g * 100 ms).
* ``large_motion``: ``--pairs`` ray-cast courtyard pairs, 32 beams, yaw U[-180, 180] deg, |t| U[0, 10] m.
* ``sequences``: ``--sequences`` courtyard drives of ``--seq-scans`` ticks at 10 Hz, 1-10 m/s, with dropouts,
  a stop-and-go, a 40 deg/s yaw swing and a kidnap (5-8 m, 30-90 deg).
* ``corridor``: ``--corridor-scans`` scans at 1.5 m/s along a featureless corridor (x unobservable).
* ``fast_gaps``: ``--fast-drives`` courtyard crossings at 15-25 m/s (10 Hz), each with one gap of 0.5-1 s in
  which the car keeps its speed or brakes (up to 6 m/s^2).
* ``speed``: the 6 KITTI scans played ping-pong for ``--speed-scans`` scans; median ms per scan.

Every method sees the same points (float64, sensor frame). ``ScanAligner`` is used with default parameters;
KISS-ICP with its default config (max_range of the sensor, voxel = max_range / 100), a fresh instance per
pair/sequence; small_gicp GICP scan-to-scan from the identity. The peers have no failure flag: all their
steps count as accepted. Exceptions are caught per step and counted as failures with their message.
The benchmark itself is the package's ``benchmarks``; this is its command line.

    python scripts/bench_robustness.py --quick
    python scripts/bench_robustness.py --sets large_motion sequences --pairs 40 --out results/robust.json
    python scripts/bench_robustness.py --methods cemnet --set recovery.search.n_scatter=125   # other parameters
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

from benchmarks.odometry import METHODS  # noqa: E402
from benchmarks.robustness import FULL, QUICK, SETS, RobustnessConfig, run  # noqa: E402
from cemnet_ros.io.atomic import write_report  # noqa: E402
from cemnet_ros.pipeline.config import AlignerConfig  # noqa: E402
from cemnet_ros.schema import build  # noqa: E402
from cemnet_ros.tools.cli_errors import reported_errors  # noqa: E402

PROG = "bench_robustness.py"


def parse_args(argv: Optional[list[str]]) -> tuple[RobustnessConfig, Path]:
    """The benchmark's configuration and the JSON path."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", nargs="+", choices=SETS, default=list(SETS), help="sets to run (default: all)")
    parser.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS),
                        help="methods (peers need the optional `bench` extra; missing ones are left out)")
    parser.add_argument("--quick", action="store_true", help=f"tiny sizes for a smoke run: {QUICK}")
    parser.add_argument("--pairs", type=int, help=f"large_motion pairs (default {FULL['pairs']})")
    parser.add_argument("--sequences", type=int, help=f"synthetic drives (default {FULL['sequences']})")
    parser.add_argument("--seq-scans", type=int, help=f"ticks per drive at 10 Hz (default {FULL['seq_scans']})")
    parser.add_argument("--corridor-scans", type=int, help=f"corridor scans (default {FULL['corridor_scans']})")
    parser.add_argument("--fast-drives", type=int, help=f"fast_gaps drives (default {FULL['fast_drives']})")
    parser.add_argument("--speed-scans", type=int, help=f"KITTI ping-pong scans (default {FULL['speed_scans']})")
    parser.add_argument("--max-gap", type=int, help=f"kitti_gaps: largest g in (i, i+g) (default {FULL['max_gap']})")
    parser.add_argument("--seed", type=int, default=0, help="base seed (large_motion: seed, sequences: seed + 100 + k, "
                                                             "corridor: seed + 200, fast_gaps: seed + 300 + k)")
    parser.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE", dest="overrides",
                        help="node parameters of the pipeline under test, e.g. recovery.search.n_scatter=125 (a "
                        "value is read as YAML: numbers, lists, strings)")
    parser.add_argument("--out", type=Path, default=REPO / "results" / "bench_robustness.json", help="JSON output")
    args = parser.parse_args(argv)
    sizes = {key: value if getattr(args, key) is None else getattr(args, key)
             for key, value in (QUICK if args.quick else FULL).items()}
    if not all("=" in item for item in args.overrides):
        parser.error("--set takes KEY=VALUE items")
    try:
        overrides = {key: yaml.safe_load(value) for key, value in (item.split("=", 1) for item in args.overrides)}
        build(AlignerConfig(), overrides)  # an unknown key or a bad value: a usage error now, not in every step
        config = RobustnessConfig(tuple(args.sets), tuple(args.methods), **sizes, seed=args.seed, overrides=overrides)
    except ValueError as exc:
        parser.error(str(exc))
    return config, args.out


def main(argv: Optional[list[str]] = None) -> int:
    config, out = parse_args(argv)
    with reported_errors(PROG) as outcome:
        report = run(config, after_set=lambda partial: write_report(out, partial.to_json()))
        print(report.to_markdown())
        write_report(out, report.to_json())
        print(f"\nwrote {out}")
    return outcome.code


if __name__ == "__main__":
    sys.exit(main())
