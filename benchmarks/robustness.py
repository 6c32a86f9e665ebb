"""The robustness benchmark as one call: :func:`run` takes a :class:`RobustnessConfig` (sets, methods, sizes,
seed) and returns a :class:`RobustnessReport` (markdown tables, JSON of every step).

Every method sees the same points (float64, sensor frame); exceptions are caught per step and counted as
failures with their message. Seeds are fixed: large_motion ``seed``, sequences ``seed + 100 + k``, corridor
``seed + 200``, fast_gaps ``seed + 300 + k``.
"""
from __future__ import annotations

import dataclasses
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Optional

from benchmarks.corridor import CORRIDOR_MAX_SCANS, run_corridor
from benchmarks.drives import MIN_SEQ_TICKS
from benchmarks.fast_gaps import run_fast_gaps
from benchmarks.odometry import METHODS, available_methods
from benchmarks.pairs import kitti_pairs, large_motion_pairs, run_pairs
from benchmarks.sequences import run_sequences
from benchmarks.shared import SHARED
from benchmarks.speed import run_speed
from benchmarks.streams import warm_up
from benchmarks.tables import report_markdown
from cemnet_ros.io.console import log
from cemnet_ros.io.report import Report

SETS = ("kitti_gaps", "large_motion", "sequences", "corridor", "fast_gaps", "speed")
KITTI_SETS = ("kitti_gaps", "speed")
FULL = {"pairs": 40, "sequences": 3, "seq_scans": 100, "corridor_scans": 60, "fast_drives": 8, "speed_scans": 60,
        "max_gap": 5}
QUICK = {"pairs": 3, "sequences": 1, "seq_scans": 60, "corridor_scans": 12, "fast_drives": 1, "speed_scans": 10,
         "max_gap": 1}


@dataclass(frozen=True)
class RobustnessConfig:
    """Sets and methods to run, their sizes (defaults: :data:`FULL`), the base seed and the KITTI sample folder
    (absent: the KITTI sets are skipped)."""

    sets: tuple[str, ...] = SETS
    methods: tuple[str, ...] = METHODS
    pairs: int = FULL["pairs"]  # large_motion pairs
    sequences: int = FULL["sequences"]  # synthetic drives
    seq_scans: int = FULL["seq_scans"]  # ticks per drive at 10 Hz
    corridor_scans: int = FULL["corridor_scans"]
    fast_drives: int = FULL["fast_drives"]  # fast_gaps drives
    speed_scans: int = FULL["speed_scans"]  # KITTI ping-pong scans
    max_gap: int = FULL["max_gap"]  # kitti_gaps: largest g in (i, i + g)
    seed: int = 0
    kitti: Path = SHARED / "data" / "kitti_sample"
    overrides: dict = field(default_factory=dict)  # dotted parameters of the pipeline under test (default: none)

    def __post_init__(self) -> None:
        unknown = sorted(set(self.sets) - set(SETS)) + sorted(set(self.methods) - set(METHODS))
        if unknown:
            raise ValueError(f"unknown set(s) or method(s) {unknown}")
        for key, value in self.sizes().items():
            if value < 1:
                raise ValueError(f"--{key.replace('_', '-')} must be >= 1")
        if self.seq_scans < MIN_SEQ_TICKS:
            raise ValueError(f"--seq-scans must be >= {MIN_SEQ_TICKS} to hold the events")
        if self.corridor_scans > CORRIDOR_MAX_SCANS:
            raise ValueError(f"--corridor-scans must be <= {CORRIDOR_MAX_SCANS}: longer drives see the corridor's ends")

    def sizes(self) -> dict[str, int]:
        return {key: getattr(self, key) for key in FULL}

    def seeds(self) -> dict[str, Any]:
        return {"large_motion": self.seed, "sequences": [self.seed + 100 + k for k in range(self.sequences)],
                "corridor": self.seed + 200, "fast_gaps": [self.seed + 300 + k for k in range(self.fast_drives)]}


@dataclass
class RobustnessReport(Report):
    """The results per set (a set's JSON as :mod:`benchmarks.tables` reads it), the methods that ran, the
    sets skipped (with why) and when it started."""

    config: RobustnessConfig
    methods: list[str]
    started: str
    results: dict[str, Any] = field(default_factory=dict)
    skipped: list[str] = field(default_factory=list)

    def to_markdown(self) -> str:
        head = [f"skip {line}" for line in self.skipped]
        changed = ", ".join(f"{k}={v}" for k, v in self.config.overrides.items())
        head.append(f"seeds: {self.config.seeds()}; methods: {', '.join(self.methods)}"
                    + (f"; cemnet with {changed}" if changed else "") + "\n")
        return "\n".join(head) + "\n" + report_markdown(self.results)

    def as_dict(self) -> dict[str, Any]:
        meta = {"config": dataclasses.asdict(self.config), "sizes": self.config.sizes(),
                "seeds": self.config.seeds(), "methods": self.methods, "skipped": self.skipped,
                "python": platform.python_version(), "machine": platform.machine(), "started": self.started}
        return {"meta": meta, "sets": self.results}


def run_set(name: str, config: RobustnessConfig, methods: dict[str, Callable]) -> dict:
    """One set's results: every method on the same scans."""
    if name == "kitti_gaps":
        return run_pairs(kitti_pairs(config.kitti, config.max_gap), methods, 100.0, name)
    if name == "large_motion":
        log(f"large_motion: ray-casting {config.pairs} pairs (seed {config.seed})")
        return run_pairs(large_motion_pairs(config.pairs, config.seed), methods, 100.0, name)
    if name == "sequences":
        return run_sequences(config.sequences, config.seq_scans, config.seed + 100, methods)
    if name == "corridor":
        return run_corridor(config.corridor_scans, config.seed + 200, methods)
    if name == "fast_gaps":
        return run_fast_gaps(config.fast_drives, config.seed + 300, methods)
    return run_speed(config.kitti, config.speed_scans, methods)


def run(config: RobustnessConfig, after_set: Optional[Callable[[RobustnessReport], None]] = None
        ) -> RobustnessReport:
    """Every set of ``config`` through every importable method; ``after_set(report)`` is called after each set
    with the results so far (e.g. to write them: a long run keeps what it measured)."""
    methods = available_methods(list(config.methods), config.overrides)
    report = RobustnessReport(config, list(methods), time.strftime("%Y-%m-%dT%H:%M:%S%z"))
    log(f"methods: {', '.join(methods) or 'none'}; seeds: {config.seeds()}")
    warm_up(methods)
    for name in config.sets:
        if name in KITTI_SETS and not config.kitti.is_dir():
            report.skipped.append(f"{name}: the KITTI sample (../shared/data/kitti_sample) is absent")
            continue
        start = time.perf_counter()
        report.results[name] = run_set(name, config, methods)
        log(f"{name}: done in {time.perf_counter() - start:.0f} s")
        if after_set is not None:
            after_set(report)
    return report
