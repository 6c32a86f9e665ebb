"""A live node's worker queue, played on a virtual clock: what the node would align at RATE x a bag's timing.

Scans arrive at their stamps (relative to the first) divided by the rate; the worker takes the oldest waiting
scan when it is free and spends on it the time its processing really takes here; a full queue drops its oldest
waiting scan, as :class:`~cemnet_ros.runtime.worker.BoundedWorker` does. The scan is handed the number of
newer scans waiting when it starts (its backlog: the node spends less on a scan while behind). The clock is
virtual, so the play takes only the processing time, yet every start, drop and latency is the one the node's
queue would see on this machine.
"""
from __future__ import annotations

import collections
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Iterator, Optional

import numpy as np

from cemnet_ros.runtime.arrival_period import ArrivalPeriod


@dataclass
class LiveScan:
    """One scan's fate in the play (seconds on the virtual clock from the first arrival)."""

    index: int
    arrival_s: float
    start_s: Optional[float] = None  # None: dropped from the queue
    finish_s: Optional[float] = None
    backlog: int = 0  # newer scans waiting when it started

    @property
    def dropped(self) -> bool:
        return self.start_s is None

    @property
    def latency_s(self) -> Optional[float]:
        """Arrival to the end of its processing (what a consumer of the odometry waits)."""
        return None if self.finish_s is None else self.finish_s - self.arrival_s


def play_live(items: Iterable[Any], stamp_ns: Callable[[Any], int], rate: float, queue_size: int,
              handle: Callable[[Any, int, Optional[float]], None]) -> list[LiveScan]:
    """Play ``items`` (in stamp order) at ``rate`` x their timing into a queue of ``queue_size``; ``handle(item,
    backlog, period_s)`` processes one (``period_s``: the arrivals' period so far, as the node measures it; None
    before three). Returns every item's :class:`LiveScan`, in arrival order."""
    if rate <= 0 or queue_size < 1:
        raise ValueError("rate must be > 0 and queue_size >= 1")
    scans: list[LiveScan] = []
    waiting: collections.deque = collections.deque()  # (LiveScan, item)
    upcoming: Iterator[Any] = iter(items)
    first_ns: Optional[int] = None
    free_s = 0.0  # when the worker is free
    arrivals = ArrivalPeriod()
    nxt = next(upcoming, None)
    while nxt is not None or waiting:
        if nxt is not None:
            first_ns = stamp_ns(nxt) if first_ns is None else first_ns
            arrival = (stamp_ns(nxt) - first_ns) * 1e-9 / rate
            if not waiting or arrival <= max(free_s, waiting[0][0].arrival_s):  # it arrives before the next start
                if len(waiting) >= queue_size:
                    waiting.popleft()  # dropped: its LiveScan keeps start_s None
                scans.append(LiveScan(len(scans), arrival))
                arrivals.arrived(arrival)
                waiting.append((scans[-1], nxt))
                nxt = next(upcoming, None)
                continue
        scan, item = waiting.popleft()
        scan.start_s, scan.backlog = max(free_s, scan.arrival_s), len(waiting)
        began = time.perf_counter()
        handle(item, scan.backlog, arrivals.seconds)
        free_s = scan.start_s + time.perf_counter() - began
        scan.finish_s = free_s
    return scans


def live_summary(scans: list[LiveScan]) -> dict[str, Any]:
    """Processed and dropped counts, latency percentiles (ms) and how many scans started behind."""
    latencies = [1e3 * s.latency_s for s in scans if s.latency_s is not None]
    processed = len(latencies)
    return {"scans": len(scans), "processed": processed, "dropped": len(scans) - processed,
            "processed_share": processed / len(scans) if scans else 0.0,
            "behind": sum(s.backlog > 0 for s in scans if not s.dropped), **latency_percentiles(latencies)}


def latency_percentiles(latencies_ms: list[float]) -> dict[str, Optional[float]]:
    """``latency_ms_p50``, ``_p95``, ``_p99`` of ``latencies_ms`` (None when there are none)."""
    return {f"latency_ms_p{q}": float(np.percentile(latencies_ms, q)) if latencies_ms else None
            for q in (50, 95, 99)}
