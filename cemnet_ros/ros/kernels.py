"""The numba kernels of an align node, before it subscribes: from the cache, or compiled now, and the log says which.

Without a complete kernel cache (the first start after a build, before ``cemnet-warm-kernels`` ran) the first scans
would compile the kernels for about a minute while the queue drops scans. :func:`prepare_kernels` compiles them
first, before the node subscribes, and logs it; with a complete cache it only says so, and :func:`counted_load`
reports after the engine loaded how many kernel versions came from the cache and how many were compiled.
"""
from __future__ import annotations

import time
from typing import Any, Optional

from cemnet_ros.runtime.aligner_session import AlignerSession
from cemnet_ros.runtime.kernel_warmup import cache_complete, cache_counts, cache_folder
from cemnet_ros.tools.warm_kernels import warm_up

AHEAD = "`ros2 run cemnet_ros cemnet-warm-kernels` after a build does it ahead"


def prepare_kernels(logger: Any) -> None:
    """Compile the kernels now unless the cache is complete (:func:`~cemnet_ros.runtime.kernel_warmup.cache_complete`);
    every outcome is one log line (a warm-up that fails is a warning: the first scans then compile)."""
    folder = cache_folder()
    if cache_complete(folder):
        logger.info(f"numba kernels: the cache {folder} is complete; they load from it with the engine")
        return
    where = f"no complete cache in {folder}" if folder else "no writable cache folder (set NUMBA_CACHE_DIR)"
    logger.warn(f"numba kernels: {where}: compiling them now, before subscribing (about a minute on 2 cores, once "
                f"per install; {AHEAD})")
    try:
        done = warm_up()
    except Exception as exc:  # noqa: BLE001 - the node still runs: its first scans compile instead
        logger.warn(f"numba kernels: the warm-up failed ({type(exc).__name__}: {exc}); the first scans compile them")
        return
    kept = f"cached in {done.folder}" if done.folder else "not cached (no writable folder)"
    logger.info(f"numba kernels: {done.compiled} versions compiled, {done.loaded} loaded from the cache, in "
                f"{done.seconds:.1f} s; {kept}; subscribing now")


def counted_load(session: AlignerSession) -> tuple[Optional[float], str]:
    """Load the session's engine: its seconds (None: it failed) and how its kernels came, e.g. "numba kernels: 15
    loaded from the cache, 0 compiled" (counted around the load, this thread's and any other's alike)."""
    start = time.monotonic()
    try:
        loaded, compiled = cache_counts()  # imports the kernel modules (torch with them), as the load would
    except Exception:  # noqa: BLE001 - the load fails on it too, and its fatal_error says why
        return session.load(), ""
    seconds = session.load()
    loaded_after, compiled_after = cache_counts()
    if seconds is None:
        return None, ""
    loaded, compiled = loaded_after - loaded, compiled_after - compiled
    already = "; already in this process" if loaded == compiled == 0 else ""
    return time.monotonic() - start, f"numba kernels: {loaded} loaded from the cache, {compiled} compiled{already}"
