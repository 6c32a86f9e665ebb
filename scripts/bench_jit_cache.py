"""Kernels loaded from numba's on-disk cache against kernels compiled in the process: same work, fresh processes.

    python scripts/bench_jit_cache.py --runs 8 --threads 1 --out results/bench_jit_cache.json

Each run starts one child process per variant, in alternating order (fresh, cached, cached, fresh, ...), so
that load from other work on the machine falls on both alike. A child makes the kernels ready (``compiled``:
``compile_kernels`` with the cache off, numba's default; ``cached``: the same calls with ``cache=True``, loaded
from a cache directory filled once beforehand), then times the work that matters:

- ``plain`` / ``fused``: the lattice rewards of 1000 motions of a 768-point pair (the CEM's CPU inner loop),
  the fastest of ``--reps`` calls;
- ``lattice``: building the lattices of that pair, the fastest of ``--reps``;
- ``scan``: ScanAligner.process on the bundled KITTI bag's scans, the mean per scan after the first (its map);
  the fastest of ``--passes`` passes (the aligner reset in between: each pass does the same work).

Other work on the machine only ever adds time, hence the fastest figures; ``--threads 1`` (numba's threads)
also keeps a kernel from waiting on a thread that another process pre-empted.

Prints, per figure, the median over runs of each variant, its spread (min-max of the runs' medians) and the
ratio cached / compiled of each run's pair (median, min-max); writes every child's figures to ``--out``
(atomically).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BAG = REPO / "bags" / "kitti_00_6scans.mcap"
FIGURES = ("ready_s", "plain_ms", "fused_ms", "lattice_ms", "scan_ms")


def _fastest_ms(call, reps: int) -> float:
    times = []
    for _ in range(reps):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return min(times) * 1e3


def child(cached: bool, reps: int, passes: int) -> dict:
    """One variant's figures in this process (the cache policy is set before any kernel module is imported)."""
    start = time.perf_counter()
    from cemnet_ros.core import jit

    jit.CACHE = cached
    import numpy as np

    from cemnet_ros.core import lattice_rewards
    from cemnet_ros.core.geometry import euler_to_matrix_np
    from cemnet_ros.core.lattice import build_lattice
    from cemnet_ros.data.shapes import bracket_shape
    from cemnet_ros.pipeline.aligner import ScanAligner
    from cemnet_ros.pipeline.steps import preprocess, refine
    from cemnet_ros.replay.bag_io import BagReader

    lattice_rewards.compile_kernels()
    preprocess.compile_kernels()
    refine.compile_kernels()
    ready = time.perf_counter() - start

    rng = np.random.default_rng(0)
    source = bracket_shape(768, seed=1).astype(np.float64)
    target = bracket_shape(768, seed=2).astype(np.float64)
    eps = 0.1  # the paper's epsilon (network units)
    spacing = eps * lattice_rewards.LATTICE_SPACING
    rots = np.ascontiguousarray(euler_to_matrix_np(rng.normal(0, 0.2, (1000, 3))))
    transs = np.ascontiguousarray(rng.normal(0, 0.05, (1000, 3)))
    pair = lattice_rewards.LatticePair.build(source, target, eps, spacing)
    pair.icp_target = build_lattice(target, 2 * eps, spacing)
    figures = {
        "ready_s": ready,
        "plain_ms": _fastest_ms(lambda: pair.rewards(rots, transs, eps), reps),
        "fused_ms": _fastest_ms(lambda: pair.fused_rewards(rots, transs, eps, 2 * eps, 1, 0.5), reps),
        "lattice_ms": _fastest_ms(lambda: lattice_rewards.LatticePair.build(source, target, eps, spacing), reps),
    }
    with BagReader(BAG) as reader:
        frames = list(reader.clouds())
    aligner, per_pass = ScanAligner(), []
    for _ in range(passes):
        aligner.reset()
        aligner.process(frames[0].points, frames[0].stamp_ns, frames[0].times, frame_id=frames[0].frame_id)
        begin = time.perf_counter()
        for frame in frames[1:]:
            aligner.process(frame.points, frame.stamp_ns, frame.times, frame_id=frame.frame_id)
        per_pass.append((time.perf_counter() - begin) / (len(frames) - 1))
    figures["scan_ms"] = min(per_pass) * 1e3
    return figures


def _run_child(cached: bool, cache_dir: Path, args: argparse.Namespace) -> dict:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache_dir), "PYTHONPATH": str(REPO)}
    if args.threads:
        env["NUMBA_NUM_THREADS"] = str(args.threads)
    command = [sys.executable, __file__, "--child", "cached" if cached else "compiled", "--reps", str(args.reps),
               "--passes", str(args.passes)]
    out = subprocess.run(command, env=env, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def _summary(runs: dict[str, list[dict]]) -> dict:
    table = {}
    for figure in FIGURES:
        row = {}
        for variant, figures in runs.items():
            values = [f[figure] for f in figures]
            row[variant] = {"median": statistics.median(values), "min": min(values), "max": max(values)}
        paired = [c[figure] / f[figure] for c, f in zip(runs["cached"], runs["compiled"])]
        row["ratio_cached_compiled"] = {"median": statistics.median(paired), "min": min(paired), "max": max(paired)}
        table[figure] = row
    return table


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=8, help="child processes per variant")
    parser.add_argument("--reps", type=int, default=30, help="timed calls per kernel figure in each child")
    parser.add_argument("--passes", type=int, default=3, help="times the bag's scans go through the aligner")
    parser.add_argument("--threads", type=int, default=0, help="numba's threads in the children (0: its default)")
    parser.add_argument("--out", type=Path, default=None, help="JSON with every child's figures")
    parser.add_argument("--child", choices=("compiled", "cached"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args.child == "cached", args.reps, args.passes)))
        return 0
    runs: dict[str, list[dict]] = {"compiled": [], "cached": []}
    with tempfile.TemporaryDirectory(prefix="numba-cache-") as cache_dir:
        _run_child(True, Path(cache_dir), args)  # fills the cache
        for run in range(args.runs):
            order = (False, True) if run % 2 == 0 else (True, False)
            for cached in order:
                figures = _run_child(cached, Path(cache_dir), args)
                runs["cached" if cached else "compiled"].append(figures)
                print(f"run {run + 1}: {'cached  ' if cached else 'compiled'} "
                      + " ".join(f"{k} {v:.2f}" for k, v in figures.items()), flush=True)
    table = _summary(runs)
    print(f"\n{'figure':<11} {'compiled: median (min-max)':>28} {'cached: median (min-max)':>28} "
          f"{'cached / compiled, per run':>28}")
    for figure, row in table.items():
        cells = [f"{row[v]['median']:.3g} ({row[v]['min']:.3g}-{row[v]['max']:.3g})"
                 for v in ("compiled", "cached", "ratio_cached_compiled")]
        print(f"{figure:<11} {cells[0]:>28} {cells[1]:>28} {cells[2]:>28}")
    if args.out:
        from cemnet_ros.io.atomic import json_text, write_report

        write_report(args.out, json_text({"runs": runs, "summary": table, "args": vars(args)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
