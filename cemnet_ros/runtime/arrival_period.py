"""The usual time between arriving scans, by the clock they arrive on: what a live scan's budget is counted in
(a sensor's period; a bag played at 2x arrives twice as often as its stamps say)."""
from __future__ import annotations

import collections
import threading
from typing import Optional

WINDOW = 21  # arrivals whose intervals' median is the period (a pause in the input is one interval of 20)


class ArrivalPeriod:
    """The median interval between the last ``WINDOW`` arrivals (thread-safe: fed by one thread, read by another)."""

    def __init__(self) -> None:
        self._times: collections.deque = collections.deque(maxlen=WINDOW)
        self._lock = threading.Lock()

    def arrived(self, t_s: float) -> None:
        with self._lock:
            self._times.append(float(t_s))

    @property
    def seconds(self) -> Optional[float]:
        """The period (s); None before three arrivals, or when they did not move forward."""
        with self._lock:
            times = list(self._times)
        intervals = sorted(b - a for a, b in zip(times, times[1:]) if b > a)
        return intervals[len(intervals) // 2] if len(intervals) >= 2 else None
