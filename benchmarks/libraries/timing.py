"""Interleaved timing: every method once per round, so that other load on the machine falls on all alike."""
from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any, Callable, Mapping, Optional

import numpy as np

from benchmarks.libraries.peers import OURS
from benchmarks.metrics import percentile

OTHERS = "others_cores"  # the key, in a times dict, of each round's load from other processes (cores in use)
QUIET_CORES = 0.25  # a round during which other processes used less than this is a quiet one
TICK_S = 1.0 / os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 0.01


def cpu_ticks() -> Optional[tuple[int, int]]:
    """(busy ticks of the whole machine, steal included; ticks of this process) from /proc, None without it."""
    try:
        machine = Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]
        own = Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return sum(int(machine[i]) for i in (0, 1, 2, 5, 6, 7)), int(own[11]) + int(own[12])


def interleaved(calls: Mapping[str, Callable[[], Any]], rounds: int, times: dict[str, list[float]]) -> dict[str, Any]:
    """Run every call once per round, in turn; append each one's ms to ``times[name]`` and the round's load from
    other processes to ``times[OTHERS]`` (nan without /proc). Returns the last outputs."""
    outputs = {}
    for _ in range(rounds):
        before, start = cpu_ticks(), time.perf_counter()
        for name, call in calls.items():
            call_start = time.perf_counter()
            outputs[name] = call()
            times.setdefault(name, []).append(1e3 * (time.perf_counter() - call_start))
        after, wall_s = cpu_ticks(), time.perf_counter() - start
        others = np.nan
        if before is not None and after is not None:
            others = ((after[0] - before[0]) - (after[1] - before[1])) * TICK_S / wall_s
        times.setdefault(OTHERS, []).append(others)
    return outputs


def timing_summary(times: dict[str, list[float]]) -> dict[str, dict]:
    """Per method: median and p90 ms, samples, and the median over rounds of ours / method (when ours ran); the
    same over the quiet rounds only (other processes below QUIET_CORES): a dedicated machine's figure."""
    others = np.asarray(times.get(OTHERS, []))
    out = {}
    for name, ms in times.items():
        if name == OTHERS:
            continue
        row: dict[str, Any] = {"ms_median": percentile(ms, 50), "ms_p90": percentile(ms, 90), "samples": len(ms)}
        if len(others) == len(ms):
            quiet = others < QUIET_CORES
            row.update(quiet_rounds=int(quiet.sum()), ms_median_quiet=percentile(list(np.asarray(ms)[quiet]), 50))
        if OURS in times and name != OURS:
            ratios = np.asarray(times[OURS]) / np.asarray(ms)
            row["ours_over"] = float(np.median(ratios))
            if "quiet_rounds" in row:
                row["ours_over_quiet"] = percentile(list(ratios[others < QUIET_CORES]), 50)
        out[name] = row
    return out
