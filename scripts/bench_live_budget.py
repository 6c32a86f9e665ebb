#!/usr/bin/env python3
"""The scan budget live: each real set played into the node's session and queue at RATE x its timing (the
virtual clock of ``cemnet_ros.replay.realtime``), with each ``scan_budget``, judged as scripts/bench_real.py
judges (accepted / flagged, right / wrong, on the scans processed).

    python scripts/bench_live_budget.py --real-sets DATA --sets quick_shack --budgets 0 2 --rates 1 2 4
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Optional

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # runnable from a fresh checkout without `pip install`
    sys.path.insert(0, str(REPO))

from benchmarks.live import live_run  # noqa: E402
from benchmarks.real import REAL_SETS, real_set  # noqa: E402
from cemnet_ros.io.atomic import json_text, write_report  # noqa: E402
from cemnet_ros.ros.node_config import NodeConfig  # noqa: E402

COLUMNS = ("set", "rate", "scan_budget", "processed", "latency p50 / p95 / p99 ms", "ATE m",
           "accepted right / wrong, flagged right / wrong", "accepted wrong steps (index, deg)")


def row_text(row: dict) -> str:
    wrong = ", ".join(f"{s['index']} ({s['error_deg']:.1f})" for s in row["accepted_wrong_steps"]) or "-"
    ate = "-" if row["ate_m"] is None else f"{row['ate_m']:.3f}"
    return (f"| {row['set']} | {row['rate']:g}x | {row['scan_budget']:g} | {row['processed']} / {row['scans']} | "
            f"{row['latency_ms_p50']:.0f} / {row['latency_ms_p95']:.0f} / {row['latency_ms_p99']:.0f} | {ate} | "
            f"{row['accepted_right']} / {row['accepted_wrong']} / {row['flagged_right']} / {row['flagged_wrong']} | "
            f"{wrong} |")


def main(argv: Optional[list[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--real-sets", type=Path, required=True, help="the folder real_sets.py extracted into")
    parser.add_argument("--sets", nargs="+", choices=REAL_SETS, default=list(REAL_SETS))
    parser.add_argument("--budgets", type=float, nargs="+", default=[0.0, NodeConfig().scan_budget])
    parser.add_argument("--rates", type=float, nargs="+", default=[1.0, 2.0, 4.0])
    parser.add_argument("--out", type=Path, default=REPO / "results" / "bench_live_budget.json")
    args = parser.parse_args(argv)
    rows = []
    print("| " + " | ".join(COLUMNS) + " |\n|" + "---|" * len(COLUMNS), flush=True)
    for name in args.sets:
        sequence = real_set(args.real_sets, name)
        for rate in args.rates:
            for budget in args.budgets:
                row = {"set": name, "scan_budget": budget, **live_run(sequence, rate, node=NodeConfig(
                    scan_budget=budget))}
                rows.append(row)
                print(row_text(row), flush=True)
    write_report(args.out, json_text({"rows": rows}))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
