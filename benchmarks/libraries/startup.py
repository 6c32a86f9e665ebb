"""Start-up of each library: import and first-call ms in fresh processes (ours: numba's compilation or cache)."""
from __future__ import annotations

import inspect
import json
import os
import subprocess
import sys
import tempfile
from functools import partial
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np

from benchmarks.libraries.inputs import Stage, Step, box_scan
from benchmarks.libraries.local_maps import downsample_calls, local_maps
from benchmarks.libraries.peers import OURS, PEER_MODULES, THREADS, import_peers
from benchmarks.libraries.timing import OTHERS, interleaved
from cemnet_ros.core.geometry import rigid_transform, so3_exp
from cemnet_ros.io.console import log, progress
from cemnet_ros.pipeline.config import AlignerConfig

IMPORTS = {OURS: ("cemnet_ros.pipeline.steps.preprocess", "cemnet_ros.pipeline.map.voxel_map",
                  "cemnet_ros.pipeline.steps.refine"),
           "small_gicp": PEER_MODULES["small_gicp"], "kiss_icp": PEER_MODULES["kiss_icp"]}
FIRST_CALL_MAP = {OURS: OURS, "small_gicp": "small_gicp plane", "kiss_icp": "kiss_icp p2p"}


def first_calls(library: str) -> dict[str, float]:
    """ms of each piece of ``library`` on a synthetic 30k-point scan, in two passes on fresh objects: the first
    pass includes numba's compilation or cache load for ours (run it in a fresh process: :func:`startup_run`)."""
    peers = {} if library == OURS else import_peers((library,))
    scan, voxel = box_scan(30_000), 0.2
    dense = scan[::3]  # not voxel_downsample's: its first call is one of those timed
    step = Step(1, [dense], [np.eye(4)], dense, dense[:3000],
                rigid_transform(so3_exp(np.array([0.0, 0.0, 0.02])), np.array([0.1, 0.0, 0.0])))
    stages = [Stage(1000, 6 * voxel, 30), Stage(3000, 2 * voxel, 10)]
    out = {}
    for which in ("first", "second"):
        local_map = local_maps(peers, AlignerConfig(), voxel, 100.0)[FIRST_CALL_MAP[library]]
        calls: dict[str, Callable] = {"downsample": downsample_calls(scan, voxel, peers)[library],
                                      "map_update": partial(local_map.insert, dense, np.eye(4)),
                                      "polish": partial(local_map.polish, step, np.eye(4), stages)}
        if library == OURS:
            calls["nearest"] = partial(local_map.map.nearest, dense, 2 * voxel)
        times: dict[str, list[float]] = {}
        interleaved(calls, 1, times)
        out.update({f"{piece}_{which}_ms": ms[0] for piece, ms in times.items() if piece != OTHERS})
    return out


def _probe(library: str, modules: tuple[str, ...]) -> dict[str, float]:
    """In a fresh process: ms to import ``modules`` (numpy already loaded: every method needs it), then
    :func:`first_calls`. Its source runs on its own in the child, hence its own imports."""
    import importlib
    import time

    import numpy  # noqa: F401 - loaded before the clock starts

    start = time.perf_counter()
    for module in modules:
        importlib.import_module(module)
    import_ms = 1e3 * (time.perf_counter() - start)
    from benchmarks.libraries.startup import first_calls

    return {"import_ms": import_ms, **first_calls(library)}


def startup_run(library: str, cache_dir: Optional[str] = None) -> dict[str, float]:
    """:func:`_probe` of ``library`` in a fresh Python process (``cache_dir``: numba's cache folder, for an empty
    one: the first-ever compilation)."""
    code = (inspect.getsource(_probe) + "\nimport json, sys\n"
            "print(json.dumps(_probe(sys.argv[1], tuple(sys.argv[2:]))))\n")
    env = dict(os.environ, NUMBA_NUM_THREADS=str(THREADS))
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = cache_dir
    repo = Path(__file__).resolve().parents[2]
    env["PYTHONPATH"] = os.pathsep.join([str(repo)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    done = subprocess.run([sys.executable, "-c", code, library, *IMPORTS[library]], env=env, capture_output=True,
                          text=True)
    if done.returncode != 0:
        raise RuntimeError(f"the start-up probe of {library} failed: {done.stderr.strip()[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def startup(libraries: list[str], runs: int, cold: bool) -> dict:
    """Median over ``runs`` fresh processes per library, interleaved, after one untimed run each (it fills ours'
    numba cache when the kernels changed); ``cold``: also ours once with an empty numba cache."""
    for library in libraries:
        startup_run(library)
    samples: dict[str, list[dict]] = {library: [] for library in libraries}
    for _ in progress(range(runs), desc="start-up"):
        for library in libraries:
            samples[library].append(startup_run(library))
    out: dict[str, Any] = {library: {key: float(np.median([s[key] for s in runs_])) for key in runs_[0]}
                           for library, runs_ in samples.items()}
    if cold and OURS in libraries:
        with tempfile.TemporaryDirectory(prefix="numba-cold-") as empty:
            log("start-up: ours with an empty numba cache (compiles these pieces' kernels)")
            out["ours, empty numba cache"] = startup_run(OURS, empty)
    return out
