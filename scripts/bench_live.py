#!/usr/bin/env python3
"""Live benchmark: real posed sequences played into the node's session at RATE x their own timing.

Per sequence: the offline run (every scan, full budgets: the same trajectory on every machine), then each rate
played into the node's queue (``cemnet_ros.replay.realtime``: drops as the node drops them, ``behind_effort``
while newer scans wait), and the peers offline (KISS-ICP, small_gicp GICP) for their time per scan. Prints
scans processed, how many started behind, latency p50 / p95 / p99 (arrival to odometry), time per step, and the
ATE, end drift and steps off (> 10 cm or 1 deg between consecutive processed scans; accepted / flagged) of what
came out. Sequences (each optional; nothing is downloaded):

* ``--balm DIR``: BALM's ``datas/benchmark_realworld`` (see scripts/bench_real.py), full and, with
  ``--thinned N``, thinned to N points per scan (fixed seed);
* ``--bag BAG``: a bag with ground truth (default: the bundled KITTI bag; ``--no-bag``: none).

    python scripts/bench_live.py --balm DIR --thinned 5000 --out results/bench_live.json
    python scripts/bench_live.py --bag bags/kitti_00_6scans.mcap --rates 1 2
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Optional

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # runnable from a fresh checkout without `pip install`
    sys.path.insert(0, str(REPO))

from benchmarks.live import bag_sequence, live_run, live_table  # noqa: E402
from benchmarks.odometry import available_methods  # noqa: E402
from benchmarks.real import balm_sequence, run_method, sequence_metrics  # noqa: E402
from benchmarks.streams import warm_up  # noqa: E402
from cemnet_ros.io.atomic import json_text, write_report  # noqa: E402
from cemnet_ros.io.console import log  # noqa: E402
from cemnet_ros.ros.node_config import NodeConfig  # noqa: E402
from cemnet_ros.tools.cli_errors import reported_errors  # noqa: E402

PROG = "bench_live.py"
PEERS = ("kiss-icp", "gicp")


def parse_args(argv: Optional[list[str]]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--balm", type=Path, help="BALM's datas/benchmark_realworld folder")
    parser.add_argument("--thinned", type=int, metavar="N", help="also BALM thinned to N random points per scan")
    parser.add_argument("--bag", type=Path, default=REPO / "bags" / "kitti_00_6scans.mcap",
                        help="a bag with ground truth")
    parser.add_argument("--no-bag", action="store_true", help="no bag (BALM only)")
    parser.add_argument("--rates", type=float, nargs="+", default=[1.0, 2.0, 4.0, 8.0],
                        help="playback rates (x the sequence's own timing)")
    parser.add_argument("--bag-rates", type=float, nargs="+", default=[1.0, 2.0], help="rates of the bag")
    parser.add_argument("--behind-effort", type=float, nargs="+", default=[NodeConfig().behind_effort],
                        help="the node's behind_effort values to compare (1 = no lighter steps while behind)")
    parser.add_argument("--limit", type=int, help="first N scans of BALM only")
    parser.add_argument("--no-peers", action="store_true", help="skip KISS-ICP and small_gicp")
    parser.add_argument("--out", type=Path, default=REPO / "results" / "bench_live.json")
    args = parser.parse_args(argv)
    if args.balm is None and args.no_bag:
        parser.error("no sequence: give --balm DIR and/or --bag BAG")
    return args


def main(argv: Optional[list[str]] = None) -> int:
    with reported_errors(PROG) as outcome:
        args = parse_args(argv)
        sets = []
        if not args.no_bag:
            sets.append((bag_sequence(args.bag), args.bag_rates))
        if args.balm is not None:
            balm = balm_sequence(args.balm, args.limit)
            sets.append((balm, args.rates))
            if args.thinned:
                thinned = balm.keyframes(1, args.thinned)
                thinned.name = f"{balm.name}_{args.thinned}pts"
                sets.append((thinned, args.rates))
        peers = {} if args.no_peers else available_methods(list(PEERS))
        warm_up({**available_methods(["cemnet"]), **peers})
        rows = []
        for sequence, rates in sets:
            for rate in [None, *rates]:
                for effort in ([1.0] if rate is None else args.behind_effort):
                    log(f"{sequence.name}: {'offline' if rate is None else f'{rate:g}x'}, behind_effort {effort:g}")
                    row = live_run(sequence, rate, node=NodeConfig(behind_effort=effort))
                    rows.append({"sequence": sequence.name, "method": f"cemnet (behind_effort {effort:g})"
                                 if rate is not None else "cemnet", "behind_effort": effort, **row})
            for name, factory in peers.items():
                log(f"{sequence.name}: {name} offline")
                metrics = sequence_metrics(sequence, run_method(factory, sequence))
                rows.append({"sequence": sequence.name, "method": name, "rate": None, "scans": metrics["scans"],
                             "processed": metrics["scans"], "behind": 0, **metrics})
        print(live_table(rows))
        write_report(args.out, json_text({"rows": rows}))
        print(f"wrote {args.out}")
    return outcome.code


if __name__ == "__main__":
    raise SystemExit(main())
