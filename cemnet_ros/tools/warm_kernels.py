"""``cemnet-warm-kernels``: compile every numba kernel of the odometry into the install's cache, ahead of the node.

A node whose kernel cache is not complete compiles the kernels at its start, before it subscribes (about a minute
on 2 cores, logged); this does it ahead, e.g. after ``colcon build`` (``ros2 run cemnet_ros cemnet-warm-kernels``) or
in an image's build, as the user (and from the same install) that runs the node: ``./run`` does it at the end of
its set-up. The kernels go where the node will look for them (:mod:`cemnet_ros.core.kernel_cache`: the package's
``__pycache__``, else the user's cache folder, or ``$NUMBA_CACHE_DIR``), and a mark there says the cache is complete
(:mod:`cemnet_ros.runtime.kernel_warmup`). The workload is the node's pipeline on a few synthetic scans, with and
without per-point times (deskewing), so that every kernel a scan reaches is compiled with the argument types the
node passes; a node without a complete cache runs the same :func:`warm_up` before it subscribes.

``--check``: fail (exit 1) when any kernel had to be compiled, i.e. the cache was not complete before this run.
"""
from __future__ import annotations

import argparse
import sys
import time
from typing import Optional

import numpy as np

from cemnet_ros.runtime.kernel_warmup import WarmUp, cache_counts, cache_folder, mark_complete

PROG = "cemnet-warm-kernels"


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


def warm_up() -> WarmUp:
    """Run the workload (compiling what the cache lacks) and mark the cache complete; the counts are this call's."""
    start = time.monotonic()
    loaded_before, compiled_before = cache_counts()
    run_workload()
    loaded, compiled = cache_counts()
    folder = cache_folder()
    if folder is not None:
        mark_complete(folder)
    return WarmUp(compiled - compiled_before, loaded - loaded_before, time.monotonic() - start, folder)


def main(argv: Optional[list[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 when a kernel was not in the cache yet")
    args = parser.parse_args(argv)
    done = warm_up()
    folder = done.folder or "nowhere (no writable folder: see the warning above)"
    print(f"{PROG}: {done.compiled} kernel versions compiled, {done.loaded} loaded from the cache, in "
          f"{done.seconds:.1f} s; the cache: {folder}")
    if args.check and done.compiled:
        print(f"{PROG}: error: the cache was not complete ({done.compiled} kernel versions compiled now)",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
