"""The peers of the library benchmark (optional ``bench`` extras) and the settings every method shares."""
from __future__ import annotations

import importlib
import importlib.metadata
import sys
from types import ModuleType
from typing import Optional

from cemnet_ros.io.console import log

THREADS = 2  # every method's thread count (numba's, small_gicp's num_threads, KISS-ICP's max_num_threads)
OURS = "ours"
NEIGHBOURS = 20  # small_gicp's default k for its normals and covariances
CONVERGENCE = 1e-4  # a step moving the points less than this (m) ends a polish: point_to_plane_icp's default
PEER_MODULES = {"small_gicp": ("small_gicp",),
                "kiss_icp": ("kiss_icp.voxelization", "kiss_icp.mapping", "kiss_icp.registration")}


def import_peers(names: tuple[str, ...] = tuple(PEER_MODULES)) -> dict[str, ModuleType]:
    """The installed peers by name (KISS-ICP's submodules loaded); each missing one is logged and left out."""
    found = {}
    for name in names:
        try:
            for module in PEER_MODULES[name]:
                importlib.import_module(module)
        except ImportError as exc:
            log(f"{name} is not installed ({exc}; pip install '.[bench]'): its column is left out")
            continue
        found[name] = sys.modules[name]
    return found


def versions() -> dict[str, Optional[str]]:
    """The installed versions of ours' runtime and of the peers (None: not installed)."""
    out: dict[str, Optional[str]] = {}
    for name in ("numpy", "numba", "scipy", "small_gicp", "kiss-icp"):
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = None
    return out
