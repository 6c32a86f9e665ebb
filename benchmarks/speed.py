"""The ``speed`` set: ms per scan of the full-resolution KITTI scans played ping-pong through each method."""
from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from benchmarks.metrics import percentile
from benchmarks.streams import run_stream
from cemnet_ros.data.kitti import kitti_scans
from cemnet_ros.io.console import log


def ping_pong_cycle(n_items: int) -> list[int]:
    """0, 1, ..., n-1, n-2, ..., 1: repeated, consecutive items are always neighbours."""
    return list(range(n_items)) + list(range(n_items - 2, 0, -1)) if n_items > 1 else [0]


def ping_pong(n_items: int, length: int) -> list[int]:
    """0, 1, ..., n-1, n-2, ..., 1, 0, 1, ... cut to ``length``: consecutive items are neighbours."""
    cycle = ping_pong_cycle(n_items)
    return [cycle[i % len(cycle)] for i in range(length)]


def run_speed(root: Path, n: int, methods: dict[str, Callable], warmup: int = 3) -> dict:
    """Median / p90 ms per scan of the full-resolution KITTI scans played ping-pong (first ``warmup`` excluded)."""
    frames = [pts.astype(np.float64) for pts, _ in kitti_scans(root)]
    order = ping_pong(len(frames), n)
    out: dict = {"points_mean": int(np.mean([len(f) for f in frames])), "scans": n, "warmup": warmup}
    for name in [m for m in ("cemnet", "kiss-icp") if m in methods]:
        log(f"speed: {n} KITTI scans through {name}")
        results = run_stream(methods[name], 100.0, [frames[i] for i in order], list(range(n)))
        timed = [s.ms for s in results[warmup:] if s.error is None]
        out[name] = {"ms_median": percentile(timed, 50), "ms_p90": percentile(timed, 90), "timed": len(timed),
                     "errors": sorted({s.error for s in results if s.error})}
    if out.get("cemnet", {}).get("ms_median") and out.get("kiss-icp", {}).get("ms_median"):
        out["ratio_cemnet_over_kiss"] = out["cemnet"]["ms_median"] / out["kiss-icp"]["ms_median"]
    return out
