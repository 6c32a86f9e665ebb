"""Start-up of the package's entry points: the first start (no kernel cache) and the starts after it.

    python scripts/bench_startup.py --out results/bench_startup.json [--runs 3] [--no-node]

Each figure is a new process's wall time, measured from just before it is started:

- ``first_odometry``: a minimal program that builds a ScanAligner and feeds it the bundled KITTI bag's first
  scans: until the first scan's odometry, and until the second's (the first motion estimate);
- ``replay``: ``cemnet-replay bags/kitti_00_6scans.mcap`` (6 scans, report and plot) until it exits;
- ``register``: ``cemnet-register`` of the bag's first two scans (saved as .npy) until it exits;
- ``node``: ``align_node`` until it logs "engine ready" (its background load: torch, weights, kernels); only
  with ROS 2 (rclpy) importable.

Every entry point gets a cache folder of its own (``NUMBA_CACHE_DIR``, empty at first): its first run is the
first start (every kernel compiled and cached), the ``--runs`` after it load the kernels from there. With
``--installed-cache`` the entry points use the install's own cache instead, as a user's do: right after ``./run``
set up the environment (which runs ``cemnet-warm-kernels``), the first run is the first start after the install.
Prints a table; writes the figures to ``--out`` atomically.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

REPO = Path(__file__).resolve().parents[1]
BAG = REPO / "bags" / "kitti_00_6scans.mcap"
FIRST_SCANS = """
import sys, time
from cemnet_ros.pipeline.aligner import ScanAligner
from cemnet_ros.replay.bag_io import BagReader

with BagReader(sys.argv[1]) as reader:
    aligner = ScanAligner()
    for frame in reader.clouds(2):
        aligner.process(frame.points, frame.stamp_ns, frame.times, frame_id=frame.frame_id)
        print(time.time(), flush=True)
"""


def _tool(name: str) -> list[str]:
    """A console script of this environment, or its module when the script is not installed."""
    script = Path(sys.executable).parent / name
    module = {"cemnet-replay": "replay_cli", "cemnet-register": "register_cli"}[name]
    return [str(script)] if script.exists() else [sys.executable, "-m", f"cemnet_ros.tools.{module}"]


def _run(command: list[str], env: dict) -> tuple[float, str]:
    """Wall seconds of ``command`` (which must succeed) and its stdout."""
    start = time.time()
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=900)
    if done.returncode != 0:
        sys.exit(f"error: {' '.join(command)} failed:\n{done.stderr[-3000:]}")
    return time.time() - start, done.stdout


def first_odometry(env: dict) -> dict:
    start = time.time()
    _, out = _run([sys.executable, "-c", FIRST_SCANS, str(BAG)], env)
    first, second = (float(line) - start for line in out.split())
    return {"first_scan_s": first, "second_scan_s": second}


def replay(env: dict, work: Path) -> dict:
    seconds, _ = _run(_tool("cemnet-replay") + [str(BAG), "--out", str(work / "replay"), "--quiet"], env)
    return {"wall_s": seconds}


def register(env: dict, work: Path) -> dict:
    seconds, _ = _run(_tool("cemnet-register") + [str(work / "scan0.npy"), str(work / "scan1.npy")], env)
    return {"wall_s": seconds}


def node(env: dict) -> dict:
    """Seconds until align_node logs that its engine is ready (its log says how long the load took)."""
    from benchmarks.dds_probe import dds_environment, node_log, start_node

    start = time.time()
    process = start_node("/bench_startup", {}, log_level="info", env={**env, **dds_environment()})
    try:
        while "engine ready" not in node_log(process):
            if process.poll() is not None or time.time() - start > 900:
                sys.exit(f"error: align_node did not load:\n{node_log(process)[-3000:]}")
            time.sleep(0.05)
        ready = time.time() - start
        line = next(line for line in node_log(process).splitlines() if "engine ready" in line)
        load = float(line.split("engine ready after ")[1].split(" s")[0])
    finally:
        process.terminate()
        process.wait(20)
    return {"engine_ready_s": ready, "load_s": load}


def _pair(work: Path) -> None:
    """The bag's first two scans as .npy files for cemnet-register."""
    import numpy as np

    from cemnet_ros.replay.bag_io import BagReader

    with BagReader(BAG) as reader:
        for k, frame in enumerate(reader.clouds(2)):
            np.save(work / f"scan{k}.npy", np.asarray(frame.points, dtype=np.float32))


def _has_ros() -> bool:
    try:
        import rclpy  # noqa: F401
    except ImportError:
        return False
    return True


def _table(results: dict) -> str:
    lines = [f"| {'entry point, figure':<34} | first start | {'later starts':<22} | median |",
             f"|{'-' * 36}|------------:|{'-' * 24}|-------:|"]
    for entry, runs in results.items():
        for figure in runs["first"]:
            later = [r[figure] for r in runs["later"]]
            lines.append(f"| {entry + ', ' + figure:<34} | {runs['first'][figure]:>9.1f} s | "
                         f"{', '.join(f'{v:.1f}' for v in later) + ' s':<22} | {statistics.median(later):>4.1f} s |")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3, help="starts after the first, per entry point")
    parser.add_argument("--out", type=Path, default=None, help="JSON with every run's figures")
    parser.add_argument("--no-node", action="store_true", help="skip align_node (also skipped without rclpy)")
    parser.add_argument("--installed-cache", action="store_true",
                        help="use the install's kernel cache (as warmed at install time), not an empty one")
    args = parser.parse_args()
    results: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="bench-startup-") as tmp:
        work = Path(tmp)
        _pair(work)
        entries: dict[str, Callable[[dict], dict]] = {
            "first_odometry": first_odometry, "replay": lambda env: replay(env, work),
            "register": lambda env: register(env, work)}
        if not args.no_node and _has_ros():
            entries["node"] = node
        for name, measure in entries.items():
            env = dict(os.environ) if args.installed_cache else {**os.environ,
                                                                 "NUMBA_CACHE_DIR": str(work / f"cache_{name}")}
            first = measure(env)
            later = [measure(env) for _ in range(args.runs)]
            results[name] = {"first": first, "later": later}
            print(f"{name}: first {first}, later {later}", flush=True)
    print(_table(results))
    if args.out:
        from cemnet_ros.io.atomic import json_text, write_report

        write_report(args.out, json_text({"results": results, "runs": args.runs, "python": sys.executable,
                                              "installed_cache": args.installed_cache}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
