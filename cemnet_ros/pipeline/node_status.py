"""What the node reports on /diagnostics, as plain code: counters, input age and rate, and the status level.

Levels follow diagnostic_msgs/DiagnosticStatus (OK 0, WARN 1, ERROR 2). No input for ``input_timeout`` is a
WARN, for 3x that an ERROR (Autoware's "no input source" check); new rejected inputs, drops, errors or flagged
steps since the last report are a WARN.
"""
from __future__ import annotations

import collections
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Optional

OK, WARN, ERROR = 0, 1, 2
RATE_WINDOW_S = 5.0  # input rate over this many seconds


@dataclass
class Report:
    level: int
    message: str
    values: dict[str, Any] = field(default_factory=dict)


class NodeStatus:
    """Thread-safe counters of one node; :meth:`report` is called by the diagnostics timer."""

    def __init__(self, input_timeout: float, clock=time.monotonic) -> None:
        self.input_timeout = float(input_timeout)
        self._clock = clock
        self._lock = threading.Lock()
        self._started = clock()
        self._arrivals: collections.deque = collections.deque()
        self.rejected: collections.Counter = collections.Counter()
        self.flagged = 0
        self.recoveries = 0
        self.ready = False  # the engine has loaded
        self.last_step: Any = None
        self._previous = (0, 0, 0, 0)  # rejected, drops, errors, flagged at the previous report

    def input_arrived(self) -> None:
        with self._lock:
            now = self._clock()
            self._arrivals.append(now)
            while self._arrivals and self._arrivals[0] < now - RATE_WINDOW_S:
                self._arrivals.popleft()

    def reject(self, kind: str) -> int:
        """Count a rejected input; its count so far."""
        with self._lock:
            self.rejected[kind] += 1
            return self.rejected[kind]

    def step_done(self, step: Any) -> None:
        with self._lock:
            self.last_step = step
            self.recoveries += int(step.recovered)
            self.flagged += int(not step.accepted)

    def input_age(self) -> Optional[float]:
        """Seconds since the last input (None: none yet)."""
        with self._lock:
            return None if not self._arrivals else self._clock() - self._arrivals[-1]

    def report(self, queue: Any, scale: Optional[float]) -> Report:
        """The status now; ``queue`` is the worker's :class:`~cemnet_ros.pipeline.worker.WorkerStats`."""
        with self._lock:
            now = self._clock()
            rejected, flagged, step, recoveries = dict(self.rejected), self.flagged, self.last_step, self.recoveries
            last = self._arrivals[-1] if self._arrivals else None
            recent = [t for t in self._arrivals if t >= now - RATE_WINDOW_S]
            span = min(RATE_WINDOW_S, now - self._started)
            rate = len(recent) / span if span > 0 else 0.0
            counts = (sum(rejected.values()), queue.drops, queue.errors, flagged)
            previous, self._previous = self._previous, counts
        age = now - (last if last is not None else self._started)
        problems = [label for label, c, p in zip(("rejected inputs", "dropped scans", "registration errors",
                                                   "flagged steps"), counts, previous) if c > p]
        level, message = (WARN, "new " + ", ".join(problems)) if problems else (OK, "ok")
        if not self.ready:
            level, message = max(level, WARN), "loading the engine; " + message
        if age > 3.0 * self.input_timeout:
            level, message = ERROR, f"no input for {age:.1f} s"
        elif age > self.input_timeout:
            level, message = max(level, WARN), f"no input for {age:.1f} s"
        values = {
            "input_age_s": "" if last is None else round(age, 3), "input_rate_hz": round(rate, 2),
            "engine_ready": self.ready, "queue_depth": queue.depth, "queue_drops": queue.drops,
            "processed": queue.processed, "errors": queue.errors,
            "latency_last_ms": round(queue.latency_last_s * 1e3, 1),
            "latency_mean_ms": round(queue.latency_mean_s * 1e3, 1),
            "latency_max_ms": round(queue.latency_max_s * 1e3, 1),
            "recoveries": recoveries, "flagged_steps": flagged, "rejected_inputs": counts[0],
            "scale_m_per_unit": "" if scale is None else round(scale, 4),
        }
        for name in ("fitness", "accepted", "reason", "recovered", "recovery_reason", "degenerate"):
            value = "" if step is None else getattr(step, name)
            values["last_" + name] = round(value, 4) if isinstance(value, float) else value
        values.update({f"rejected_{kind}": count for kind, count in sorted(rejected.items())})
        return Report(level, message, values)
