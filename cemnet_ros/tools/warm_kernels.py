"""``cemnet-warm-kernels``: compile every numba kernel of the odometry into the install's cache, at install time.

Without it the first start after an install compiles them (~30-40 s on 2 cores) before the first odometry. Run
it once after installing, as the user (and from the same install) that runs the node: ``./run`` does it at the
end of its set-up; a colcon user runs ``ros2 run cemnet_ros cemnet-warm-kernels`` after ``colcon build`` (and
after each rebuild that changes a kernel). The kernels go where the node will look for them
(:mod:`cemnet_ros.core.kernel_cache`: the package's ``__pycache__``, else the user's cache folder, or
``$NUMBA_CACHE_DIR``). The workload is the node's pipeline on a few synthetic scans, with and without per-point
times (deskewing), so that every kernel a scan reaches is compiled with the argument types the node passes.

``--check``: fail (exit 1) when any kernel had to be compiled, i.e. the cache was not complete before this run.
"""
from __future__ import annotations

import argparse
import importlib
import sys
import time
from typing import Optional

import numpy as np

PROG = "cemnet-warm-kernels"


def kernel_modules() -> list:
    """The package's modules that define kernels (:data:`~cemnet_ros.core.kernel_cache.SOURCES`), imported."""
    from cemnet_ros.core.kernel_cache import SOURCES

    return [importlib.import_module("cemnet_ros." + name[:-len(".py")].replace("/", ".")) for name in SOURCES]


def cache_counts() -> tuple[int, int]:
    """(kernel versions loaded from the cache, kernel versions compiled) in this process so far."""
    import numba

    loaded = compiled = 0
    for module in kernel_modules():
        for value in vars(module).values():
            if isinstance(value, numba.core.dispatcher.Dispatcher) and value.py_func.__module__ == module.__name__:
                loaded += sum(value.stats.cache_hits.values())
                compiled += sum(value.stats.cache_misses.values())
    return loaded, compiled


def run_workload(n_scans: int = 3) -> None:
    """The node's pipeline (default parameters) over ``n_scans`` synthetic scans, with and without point times."""
    from cemnet_ros.data.scenes import LidarModel
    from cemnet_ros.data.skewed import skewed_sequence
    from cemnet_ros.pipeline.aligner import ScanAligner

    sequence = skewed_sequence(n_scans, lidar=LidarModel(n_beams=16, n_azimuth=500))
    for with_times in (True, False):
        aligner = ScanAligner()
        for points, times, stamp_ns in zip(sequence.scans, sequence.times, sequence.stamps_ns):
            aligner.process(points.astype(np.float64), stamp_ns, times if with_times else None)


def main(argv: Optional[list[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 when a kernel was not in the cache yet")
    args = parser.parse_args(argv)
    from cemnet_ros.core.kernel_cache import cache_folder

    start = time.monotonic()
    run_workload()
    loaded, compiled = cache_counts()
    folder = cache_folder() or "nowhere (no writable folder: see the warning above)"
    print(f"{PROG}: {compiled} kernel versions compiled, {loaded} loaded from the cache, in "
          f"{time.monotonic() - start:.1f} s; the cache: {folder}")
    if args.check and compiled:
        print(f"{PROG}: error: the cache was not complete ({compiled} kernel versions compiled now)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
