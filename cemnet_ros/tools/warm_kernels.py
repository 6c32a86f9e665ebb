"""``cemnet-warm-kernels``: compile every numba kernel of the odometry into the install's cache, ahead of the node.

A node whose kernel cache is not complete compiles the kernels at its start, before it subscribes (about a minute
on 2 cores, logged); this does it ahead, e.g. after ``colcon build`` (``ros2 run cemnet_ros cemnet-warm-kernels``) or
in an image's build, as the user (and from the same install) that runs the node: ``./run`` does it at the end of
its set-up. The kernels go where the node will look for them (:mod:`cemnet_ros.core.kernel_cache`: the package's
``__pycache__``, else the user's cache folder, or ``$NUMBA_CACHE_DIR``), and a mark there says the cache is complete
(:mod:`cemnet_ros.runtime.kernel_warmup`, which also holds the workload).

``--check``: fail (exit 1) when any kernel had to be compiled, i.e. the cache was not complete before this run.
"""
from __future__ import annotations

import argparse
import sys
from typing import Optional

PROG = "cemnet-warm-kernels"


def main(argv: Optional[list[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 when a kernel was not in the cache yet")
    args = parser.parse_args(argv)
    from cemnet_ros.runtime.kernel_warmup import warm_up

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
