"""Where a scan's time goes: the node's pipeline timed stage by stage on a sequence, beside the peers' whole step.

Each stage is a function or method of the pipeline wrapped with a timer for the run (its inclusive time; a stage
called inside another, e.g. the correspondence kernel inside the fine polish, counts in both, its row says so).
The scans that ran the global search are reported apart: the question is what a step costs that tracks.
"""
from __future__ import annotations

import contextlib
import functools
import importlib
import time
from collections import defaultdict
from dataclasses import dataclass
from typing import Any, Callable, Iterator, Optional

import numpy as np

from benchmarks.real import Sequence, run_method
from cemnet_ros.io.console import progress


@dataclass(frozen=True)
class Stage:
    """One timed function: ``owner`` a module path, ``name`` an attribute of it or ``Class.method``."""

    label: str
    owner: str
    name: str


STAGES = (
    Stage("frame: voxel grid, subsets (preprocess)", "cemnet_ros.pipeline.steps.frame", "Preprocessor.frame"),
    Stage("polish, fine: point-to-plane ICP", "cemnet_ros.pipeline.steps.polish", "Polisher.fine"),
    Stage("  of which its correspondence kernel (numba)", "cemnet_ros.pipeline.steps.refine", "_normal_equations"),
    Stage("polish, wide: GICP to the map's last scan (small_gicp)", "cemnet_ros.pipeline.steps.polish",
          "Polisher.basin"),
    Stage("  of which the scans' GICP clouds (voxel grid, covariances)", "cemnet_ros.pipeline.steps.frame",
          "gicp_cloud"),
    Stage("judging: fitness and coverage (overlap)", "cemnet_ros.pipeline.map.voxel_map", "VoxelMap.overlap"),
    Stage("judging: the last scan's free space", "cemnet_ros.pipeline.steps.contest", "Contest.seen_through"),
    Stage("tracking CEM", "cemnet_ros.pipeline.steps.metric_cem", "MetricEngine.cem"),
    Stage("global search", "cemnet_ros.pipeline.steps.metric_cem", "MetricEngine.search"),
    Stage("map update: insert, normals, prune", "cemnet_ros.pipeline.map.voxel_map", "VoxelMap.update"),
)


class StageTimer:
    """Seconds spent in each stage since the last :meth:`take` (a recursive call counts once)."""

    def __init__(self) -> None:
        self._spent: dict[str, float] = defaultdict(float)
        self._depth: dict[str, int] = defaultdict(int)

    def wrap(self, label: str, function: Callable) -> Callable:
        @functools.wraps(function)
        def timed(*args: Any, **kwargs: Any) -> Any:
            self._depth[label] += 1
            start = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                self._depth[label] -= 1
                if not self._depth[label]:
                    self._spent[label] += time.perf_counter() - start
        return timed

    def take(self) -> dict[str, float]:
        spent, self._spent = dict(self._spent), defaultdict(float)
        return spent


@contextlib.contextmanager
def timed_stages(timer: StageTimer, stages: tuple[Stage, ...] = STAGES) -> Iterator[None]:
    """The stages wrapped with ``timer`` while the block runs, put back after it."""
    undo = []
    try:
        for stage in stages:
            owner: Any = importlib.import_module(stage.owner)
            *path, attribute = stage.name.split(".")
            for part in path:
                owner = getattr(owner, part)
            original = owner.__dict__[attribute] if isinstance(owner, type) else getattr(owner, attribute)
            setattr(owner, attribute, timer.wrap(stage.label, getattr(owner, attribute)))
            undo.append((owner, attribute, original))
        yield
    finally:
        for owner, attribute, original in reversed(undo):
            setattr(owner, attribute, original)


def pipeline_costs(sequence: Sequence, make_aligner: Callable[[], Any], warmup: int = 10) -> dict:
    """The pipeline over ``sequence``: per scan its total ms and each stage's; tracked scans (no global search)
    and searched ones apart; the first ``warmup`` scans left out (the map and the caches fill)."""
    aligner, timer = make_aligner(), StageTimer()
    rows = []
    with timed_stages(timer):
        for k, (points, stamp) in enumerate(progress(list(zip(sequence.scans, sequence.stamps_ns)),
                                                     desc=sequence.name)):
            timer.take()
            start = time.perf_counter()
            step = aligner.process(points, stamp)
            total = time.perf_counter() - start
            if k >= warmup:
                rows.append((bool(step.recovered), total, timer.take()))
    return {"tracked": summary([r for r in rows if not r[0]]), "searched": summary([r for r in rows if r[0]])}


def summary(rows: list[tuple[bool, float, dict[str, float]]]) -> dict:
    """Scans, p50 / mean total ms, and each stage's mean ms per scan (the rest: everything between them)."""
    if not rows:
        return {"scans": 0}
    totals = np.array([total for _, total, _ in rows]) * 1e3
    stages = {s.label: 1e3 * float(np.mean([spent.get(s.label, 0.0) for _, _, spent in rows])) for s in STAGES}
    top_level = sum(ms for label, ms in stages.items() if not label.startswith(" "))
    return {"scans": len(rows), "p50_ms": float(np.median(totals)), "mean_ms": float(totals.mean()),
            "stages_ms": stages, "rest_ms": float(totals.mean()) - top_level}


def peer_costs(sequence: Sequence, factory: Callable, warmup: int = 10) -> dict:
    """A peer's whole step over ``sequence``: p50 / mean ms over every scan after the first ``warmup`` (a peer
    has no global search to leave out)."""
    times = [step.ms for step in run_method(factory, sequence)[warmup:]]
    return {"scans": len(times), "p50_ms": float(np.median(times)), "mean_ms": float(np.mean(times))}


def decoding_costs(sequence: Sequence) -> Optional[dict]:
    """The node's PointCloud2 decoding per scan (ms p50), on the scans packed as float32 x, y, z messages (None
    without sensor_msgs)."""
    try:
        from builtin_interfaces.msg import Time
        from sensor_msgs.msg import PointCloud2, PointField
    except ImportError:
        return None
    from cemnet_ros.pointcloud2 import decode_scan, make_pointcloud2

    times = []
    for points, stamp in zip(sequence.scans, sequence.stamps_ns):
        msg = make_pointcloud2(PointCloud2, PointField, points, "sensor", Time(sec=stamp // 10 ** 9,
                                                                               nanosec=stamp % 10 ** 9))
        start = time.perf_counter()
        decode_scan(msg, stamp_ns=stamp)
        times.append(1e3 * (time.perf_counter() - start))
    return {"scans": len(times), "p50_ms": float(np.median(times))}
