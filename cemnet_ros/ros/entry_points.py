"""The nodes' console scripts (``align_node``, ``align_lifecycle_node``).

The node modules import rclpy, numpy and the pipeline: a third of a second in which a Ctrl-C (a launch stopped
at once) would raise a KeyboardInterrupt traceback and a killed-by-signal exit status. Here the import and the
start are one guarded call, so a Ctrl-C then ends the process as one later does: quietly, with status 0.
"""
from __future__ import annotations

import importlib
import sys


def align_node() -> None:
    """``align_node``: :func:`cemnet_ros.ros.align_node.main`."""
    _start("cemnet_ros.ros.align_node")


def align_lifecycle_node() -> None:
    """``align_lifecycle_node``: :func:`cemnet_ros.ros.align_lifecycle_node.main`."""
    _start("cemnet_ros.ros.align_lifecycle_node")


def _start(module: str) -> None:
    """Import ``module`` and run its ``main``; a Ctrl-C before its node spins (while importing, or between
    rclpy.init and the node's own handling: nothing to tear down yet) exits 0 without a traceback."""
    try:
        importlib.import_module(module).main()
    except KeyboardInterrupt:
        sys.exit(0)
