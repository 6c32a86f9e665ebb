#!/usr/bin/env python3
"""Library benchmark: the project's voxel grid, local map, nearest-point queries and point-to-plane polish against
small_gicp and KISS-ICP (and scipy's cKDTree), piece by piece, on real scans; and each one's start-up.

Sequences (each optional; the script downloads nothing):

* ``--kitti DIR``: the 6 KITTI sample scans, 10 Hz, ~124k points (default: ``../shared/data/kitti_sample`` when
  present).
* ``--balm DIR``: BALM's real-world benchmark, 2 Hz, ~73k points (DIR is its ``datas/benchmark_realworld``
  folder, see ``scripts/bench_real.py``), from scan ``--balm-first`` on: the first ~20 scans are at rest.

Every method gets the node's parameters at each sequence's auto scale and 2 threads; the methods run interleaved
(A, B, C, A, B, C, ...) ``--repeats`` times per input. Per sequence: ms per voxel grid of a cropped scan, per scan
inserted into a growing local map, per nearest-point query of a voxel cloud against a map of ``--map-scans``
scans; and the node's two-stage polish of ``--pairs`` steps against a map of 1 and of ``--map-scans`` scans, from
the truth offset by 0.3 m / 3 deg and 1 m / 10 deg (``--seeds`` random directions each): ms, steps, errors and
the share within 10 cm / 1 deg. Start-up: import and first-call ms in fresh processes (``--startup-runs``), ours
with its numba cache and, unless ``--no-cold``, once with an empty one. Prints tables, writes the JSON atomically.

    python scripts/bench_libraries.py --balm BALM/datas/benchmark_realworld --out results/bench_libraries.json
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Optional

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # runnable from a fresh checkout without `pip install`
    sys.path.insert(0, str(REPO))

import cemnet_ros.ros  # noqa: E402, F401 - the node's thread policy (no spinning idle pools), before numpy's and numba's
from benchmarks.libraries.peers import OURS, THREADS, import_peers, versions  # noqa: E402
from benchmarks.libraries.sequence import bench_sequence  # noqa: E402
from benchmarks.libraries.startup import startup  # noqa: E402
from benchmarks.libraries.table import libraries_table  # noqa: E402
from benchmarks.real import balm_sequence, kitti_sequence  # noqa: E402
from cemnet_ros.core.kernel_cache import kernel_digest  # noqa: E402
from cemnet_ros.io.atomic import json_text, write_report  # noqa: E402
from cemnet_ros.io.console import log  # noqa: E402
from cemnet_ros.tools.cli_errors import reported_errors  # noqa: E402

PROG = "bench_libraries.py"
SHARED_KITTI = REPO.parent / "shared" / "data" / "kitti_sample"


def parse_args(argv: Optional[list[str]]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kitti", type=Path, default=SHARED_KITTI if SHARED_KITTI.is_dir() else None,
                        help="KITTI sample folder (velodyne/, poses.txt, calib.txt)")
    parser.add_argument("--balm", type=Path, help="BALM's datas/benchmark_realworld folder")
    parser.add_argument("--balm-first", type=int, default=25, help="first BALM scan used (earlier ones are at rest)")
    parser.add_argument("--pairs", type=int, default=5, help="polish steps per sequence and map size")
    parser.add_argument("--map-scans", type=int, default=4, help="scans in the local map of the larger case")
    parser.add_argument("--seeds", type=int, default=3, help="random offset directions per step and offset size")
    parser.add_argument("--repeats", type=int, default=3, help="timed rounds per input (all methods each round)")
    parser.add_argument("--startup-runs", type=int, default=3, help="fresh processes per library (0 = none)")
    parser.add_argument("--no-cold", action="store_true", help="skip ours' start with an empty numba cache")
    parser.add_argument("--out", type=Path, default=REPO / "results" / "bench_libraries.json")
    args = parser.parse_args(argv)
    if args.balm is None and args.kitti is None:
        parser.error("no sequence: give --kitti DIR and/or --balm DIR")
    if min(args.pairs, args.map_scans, args.seeds, args.repeats) < 1 or min(args.balm_first, args.startup_runs) < 0:
        parser.error("--pairs, --map-scans, --seeds and --repeats must be >= 1, --balm-first and --startup-runs >= 0")
    return args


def main(argv: Optional[list[str]] = None) -> int:
    with reported_errors(PROG) as outcome:
        args = parse_args(argv)
        peers = import_peers()
        sequences = []
        if args.kitti is not None:
            sequences.append(kitti_sequence(args.kitti))
        if args.balm is not None:
            balm = balm_sequence(args.balm, args.balm_first + args.map_scans + args.pairs)
            del balm.scans[:args.balm_first], balm.poses[:args.balm_first], balm.stamps_ns[:args.balm_first]
            sequences.append(balm)
        results: dict = {"cores": os.cpu_count(), "threads": THREADS, "versions": versions(),
                         "kernel_digest": kernel_digest(), "args": vars(args), "load_average_start": os.getloadavg(),
                         "sequences": {}}
        for seq in sequences:
            log(f"{seq.name}: {len(seq.scans)} scans")
            results["sequences"][seq.name] = bench_sequence(seq, peers, args.pairs, args.map_scans, args.seeds,
                                                            args.repeats)
        if args.startup_runs:
            results["startup"] = startup([OURS, *peers], args.startup_runs, cold=not args.no_cold)
        results["load_average_end"] = os.getloadavg()  # other work on the machine during the run
        print(libraries_table(results))
        write_report(args.out, json_text(results))
        print(f"wrote {args.out}")
    return outcome.code


if __name__ == "__main__":
    raise SystemExit(main())
