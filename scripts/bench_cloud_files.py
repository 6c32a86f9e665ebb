#!/usr/bin/env python3
"""Point cloud files: the project's PLY / PCD readers and writers against plyfile and pypcd4.

The measurement is benchmarks/cloud_files.py.
Prints three tables: which writer's file each reader reads right, what each reader does with the malformed files
of test/io, and ms per write / read of a 1M-point cloud (the KITTI sample's scans stacked, or a seeded random
cloud without it). Needs ``pip install plyfile pypcd4`` (not dependencies of the package).

    python scripts/bench_cloud_files.py --rounds 5 --out results/bench_cloud_files.json
"""
from __future__ import annotations

import argparse
import collections
import sys
import tempfile
from pathlib import Path
from typing import Optional

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # runnable from a fresh checkout without `pip install`
    sys.path.insert(0, str(REPO))

from benchmarks.cloud_files import cross_reading, malformed, timings  # noqa: E402
from cemnet_ros.io.atomic import json_text, write_report  # noqa: E402
from cemnet_ros.io.pointcloud_files import read_points  # noqa: E402

SHARED_KITTI = REPO.parent / "shared" / "data" / "kitti_sample" / "velodyne"


def big_cloud(n: int) -> tuple[np.ndarray, str]:
    """``n`` points: the KITTI sample's scans stacked (each shifted 100 m along x), or a seeded random cloud."""
    scans = sorted(SHARED_KITTI.glob("*.bin")) if SHARED_KITTI.is_dir() else []
    if not scans:
        return np.random.default_rng(0).uniform(-50, 50, size=(n, 3)), f"{n} random points"
    parts, total, k = [], 0, 0
    while total < n:
        scan = read_points(scans[k % len(scans)]) + [100.0 * k, 0.0, 0.0]
        parts.append(scan)
        total, k = total + len(scan), k + 1
    return np.concatenate(parts)[:n], f"{n} points of {k} KITTI scans"


def main(argv: Optional[list[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=1_000_000)
    parser.add_argument("--rounds", type=int, default=5, help="timed rounds (every method once per round)")
    parser.add_argument("--out", type=Path, default=REPO / "results" / "bench_cloud_files.json")
    args = parser.parse_args(argv)
    small = np.random.default_rng(7).normal(scale=20.0, size=(500, 3))
    points, what = big_cloud(args.points)
    with tempfile.TemporaryDirectory() as folder:
        results = {"cross_reading": cross_reading(Path(folder), small), "malformed": malformed(Path(folder)),
                   "cloud": what, "timings": timings(Path(folder), points, args.rounds)}
    print("| file written by | reader | outcome |\n|---|---|---|")
    for row in results["cross_reading"]:
        print(f"| {row['file']} | {row['reader']} | {row['outcome']} |")
    print("\n| reader | malformed files: raised | malformed: returned points | well-formed edge cases | errors |")
    print("|---|---|---|---|---|")
    for reader in dict.fromkeys(row["reader"] for row in results["malformed"]):
        rows = [r for r in results["malformed"] if r["reader"] == reader]
        bad = [r for r in rows if not r["well_formed"]]
        raised = [r for r in bad if r["outcome"].startswith("error")]
        kinds = collections.Counter(r["outcome"].removeprefix("error: ") for r in raised)
        good = ", ".join(f"{r['case']}: {r['outcome']}" for r in rows if r["well_formed"])
        print(f"| {reader} | {len(raised)} of {len(bad)} | {', '.join(r['case'] for r in bad if r not in raised)} "
              f"| {good} | {', '.join(f'{k} {v}' for k, v in kinds.most_common())} |")
    print(f"\n{what}, ms (median over {args.rounds} rounds; ours / library per round, median)\n")
    print("| operation | ours ms | library | library ms | ours / library |\n|---|---|---|---|---|")
    for case, summary in results["timings"].items():
        library = next(name for name in summary if name != "ours")
        print(f"| {case} | {summary['ours']['ms_median']:.1f} | {library} | {summary[library]['ms_median']:.1f} "
              f"| {summary[library]['ours_over']:.2f} |")
    write_report(args.out, json_text(results))
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
