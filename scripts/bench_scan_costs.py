#!/usr/bin/env python3
"""Where a small scan's time goes: the node's pipeline stage by stage on a real sequence, KISS-ICP and small_gicp
GICP (scan to scan) on the same scans in the same run, and the node's PointCloud2 decoding.

Per stage, the mean ms per scan over the scans that track (no global search; those that ran it are counted
apart), the stage's share of the step, and the step's p50 against each peer's (the ratio is the figure to watch:
the machine's speed cancels out of it). Prints the table, writes the JSON atomically.

    python scripts/bench_scan_costs.py --real-sets DATA                      # quick_shack: 5k-point Livox scans
    python scripts/bench_scan_costs.py --real-sets DATA --set hku --repeats 3
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Optional

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # runnable from a fresh checkout without `pip install`
    sys.path.insert(0, str(REPO))

from benchmarks.odometry import available_methods  # noqa: E402
from benchmarks.real import REAL_SETS, real_set  # noqa: E402
from benchmarks.scan_costs import decoding_costs, peer_costs, pipeline_costs  # noqa: E402
from cemnet_ros.io.atomic import json_text, write_report  # noqa: E402
from cemnet_ros.pipeline.aligner import AlignerConfig, ScanAligner  # noqa: E402
from cemnet_ros.schema import build  # noqa: E402


def table(result: dict) -> str:
    """The stages of the tracked scans, then the whole step's p50 beside the peers'."""
    tracked = result["runs"][0]["tracked"]
    lines = [f"| {result['set']}: tracked scans ({tracked['scans']}) | ms per scan (mean) | share |", "|---|---:|---:|"]
    for label, ms in [*tracked["stages_ms"].items(), ("the rest: plan, decision, commit (Python)",
                                                      tracked["rest_ms"])]:
        lines.append(f"| {label} | {ms:.2f} | {100 * ms / tracked['mean_ms']:.0f} % |")
    lines.append(f"| **the step** | **{tracked['mean_ms']:.2f}** | |")
    lines += ["", "| method | run | ms p50 | ms mean | node's p50 / its p50 |", "|---|---:|---:|---:|---:|"]
    for i, run in enumerate(result["runs"]):
        node = run["tracked"]["p50_ms"]
        lines.append(f"| node, tracked scans | {i + 1} | {node:.2f} | {run['tracked']['mean_ms']:.2f} | 1.0 |")
        searched = run["searched"]
        if searched["scans"]:
            lines.append(f"| node, scans that searched ({searched['scans']}) | {i + 1} | {searched['p50_ms']:.1f} | "
                         f"{searched['mean_ms']:.1f} | |")
        for name, peer in run["peers"].items():
            lines.append(f"| {name} | {i + 1} | {peer['p50_ms']:.2f} | {peer['mean_ms']:.2f} | "
                         f"{node / peer['p50_ms']:.1f} |")
    if result["decoding"]:
        lines.append(f"| node's PointCloud2 decoding | | {result['decoding']['p50_ms']:.3f} | | |")
    return "\n".join(lines)


def main(argv: Optional[list[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--real-sets", type=Path, required=True,
                        help="the folder ../shared/real_sets/real_sets.py extract wrote")
    parser.add_argument("--set", choices=REAL_SETS, default="quick_shack")
    parser.add_argument("--repeats", type=int, default=2, help="runs of every method, interleaved")
    parser.add_argument("--peers", nargs="*", default=["kiss-icp", "gicp"])
    parser.add_argument("--out", type=Path, default=REPO / "results" / "bench_scan_costs.json")
    args = parser.parse_args(argv)
    sequence = real_set(args.real_sets, args.set)
    peers = {name: factory for name, factory in available_methods(args.peers).items() if name != "cemnet"}
    runs = []
    for _ in range(args.repeats):
        run = pipeline_costs(sequence, lambda: ScanAligner(build(AlignerConfig(), {})))  # the node's defaults
        run["peers"] = {name: peer_costs(sequence, factory) for name, factory in peers.items()}
        runs.append(run)
    result = {"set": args.set, "runs": runs, "decoding": decoding_costs(sequence)}
    print(table(result))
    write_report(args.out, json_text(result))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
