"""The numba kernels' warm-up: is this install's kernel cache complete, and compiling it when it is not.

A process that finds the kernels in numba's disk cache (:mod:`cemnet_ros.core.kernel_cache`) loads them in about a
second; one that does not compiles them at its first scans (about a minute on 2 cores), while a node's queue
overflows. A warm-up (:func:`warm_up`: the node's pipeline on a few synthetic scans, so that every kernel a scan
reaches is compiled with the argument types the node passes) that ran to the end leaves a mark in the cache folder
(:data:`MARK`) naming what numba's cached code depends on: the kernel sources' paths, sizes and modification times
(numba's own staleness check), numba's version, and the target and CPU it compiled for (numba's key of cached
code). :func:`cache_complete` compares the mark with this process, so a node can warm up before it subscribes
exactly when its first scans would compile (``cemnet-warm-kernels`` runs the same warm-up ahead, e.g. after a
build).
"""
from __future__ import annotations

import importlib
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np

MARK = "complete.json"


@dataclass
class WarmUp:
    """What a warm-up did: kernel versions ``compiled`` now and ``loaded`` from the cache, in ``seconds``; the cache
    ``folder`` (None: no writable folder, so nothing was kept)."""

    compiled: int
    loaded: int
    seconds: float
    folder: Optional[str]


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


def cache_mark(package: Optional[Path] = None) -> dict[str, Any]:
    """What the cached kernels depend on, for this process and the kernel sources under ``package``."""
    import numba
    from numba.core.registry import cpu_target

    from cemnet_ros.core.kernel_cache import PACKAGE, SOURCES

    package = PACKAGE if package is None else package
    sources = {}
    for name in SOURCES:
        stat = (package / name).stat()
        sources[str(package / name)] = [stat.st_mtime, stat.st_size]
    # numba's own key of cached machine code: (target triple, CPU name, CPU features)
    triple, cpu, features = cpu_target.target_context.codegen().magic_tuple()
    return {"numba": numba.__version__, "target": triple, "cpu": cpu, "cpu_features": features, "sources": sources}


def cache_folder() -> Optional[str]:
    """The kernels' cache folder of this process (None: none is writable)."""
    from cemnet_ros.core.kernel_cache import cache_folder as folder

    return folder()


def cache_complete(folder: Optional[str] = None, package: Optional[Path] = None) -> bool:
    """Whether a warm-up ran to the end in ``folder`` (default: this process's cache) for these kernel sources, this
    numba and this CPU: then the kernels load from the cache and nothing compiles at the first scans."""
    folder = cache_folder() if folder is None else folder
    if folder is None:
        return False
    try:
        mark = json.loads((Path(folder) / MARK).read_text())
    except (OSError, ValueError):
        return False
    return mark == cache_mark(package)


def warm_up() -> WarmUp:
    """Run the workload (compiling what the cache lacks) and mark the cache complete; the counts are this call's."""
    from cemnet_ros.io.atomic import atomic_write_text

    start = time.monotonic()
    loaded_before, compiled_before = cache_counts()
    run_workload()
    loaded, compiled = cache_counts()
    folder = cache_folder()
    if folder is not None:
        atomic_write_text(Path(folder) / MARK, json.dumps(cache_mark(), indent=1))
    return WarmUp(compiled - compiled_before, loaded - loaded_before, time.monotonic() - start, folder)
