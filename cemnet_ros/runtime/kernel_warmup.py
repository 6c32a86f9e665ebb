"""Whether this install's numba kernel cache is complete: the mark a finished warm-up leaves, and the check.

A process that finds the kernels in numba's disk cache (:mod:`cemnet_ros.core.kernel_cache`) loads them in about a
second; one that does not compiles them at its first scans (about a minute on 2 cores), while a node's queue
overflows. A warm-up (:func:`cemnet_ros.tools.warm_kernels.warm_up`: the node's pipeline on a few synthetic scans)
that ran to the end leaves a mark in the cache folder (:data:`MARK`, :func:`mark_complete`) naming what numba's
cached code depends on: the kernel sources' paths, sizes and modification times (numba's own staleness check),
numba's version, and the target and CPU it compiled for (numba's key of cached code). :func:`cache_complete`
compares the mark with this process, so a node warms up before it subscribes exactly when its first scans would
compile. :func:`cache_counts` says how many kernel versions a process loaded and compiled.
"""
from __future__ import annotations

import importlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

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


def mark_complete(folder: str) -> None:
    """Mark ``folder`` complete for this process's kernels: a warm-up has just run to the end there."""
    from cemnet_ros.io.atomic import atomic_write_text

    atomic_write_text(Path(folder) / MARK, json.dumps(cache_mark(), indent=1))
