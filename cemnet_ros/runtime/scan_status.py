"""What the node says about each input message, as plain code: its ``~/scan_status`` verdict and its log lines.

Every input message gets one verdict (diagnostic_msgs levels): OK for a good step, WARN for a flagged one (still
published), ERROR for a rejected input or a scan whose processing raised; its name is the message's stamp in ns
("" when the stamp could not be read). A flagged step that the search beside the worker confirms later gets a
second verdict, OK (``vouched_late``), when the node vouches for it. Each is counted in
:class:`~.node_status.NodeStatus`. Log warnings are throttled per kind (rclpy's ``throttle_duration_sec``
throttles per call site, which would hide a second kind of bad input behind the first); the first error of each
exception type is logged with its traceback.
"""
from __future__ import annotations

import threading
import time
import traceback
from dataclasses import dataclass, field
from typing import Any, Callable, Optional

from cemnet_ros.runtime.node_status import ERROR, OK, WARN, NodeStatus

WARN_PERIOD_S = 5.0  # at most one log warning per kind this often


@dataclass
class ScanVerdict:
    """One input message's ``~/scan_status``."""

    stamp_ns: Optional[int]  # None: the stamp could not be read
    level: int
    message: str
    values: dict[str, Any] = field(default_factory=dict)


@dataclass
class Outcome:
    """What the node publishes and logs about one event."""

    verdict: Optional[ScanVerdict] = None
    warnings: list[str] = field(default_factory=list)  # log warnings due now (throttled)
    error: Optional[str] = None  # a log error: the first of its exception type, with its traceback


class ScanStatus:
    """Counts what happens to each input in a NodeStatus and says what to publish and log (thread-safe)."""

    def __init__(self, status: NodeStatus, period_s: float = WARN_PERIOD_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.status = status
        self._period_s, self._clock = float(period_s), clock
        self._last_warned: dict[str, float] = {}
        self._error_types: set[str] = set()
        self._lock = threading.Lock()

    def throttled(self, kind: str, message: str) -> list[str]:
        """``[message]`` when no warning of ``kind`` was logged within the period, else ``[]``."""
        now = self._clock()
        with self._lock:
            last = self._last_warned.get(kind)
            if last is not None and now - last < self._period_s:
                return []
            self._last_warned[kind] = now
        return [message]

    def rejected(self, kind: str, message: str, stamp_ns: Optional[int]) -> Outcome:
        """An input refused before or by the aligner (``kind``: the fault, e.g. "cdr", "stamp", "unpaired")."""
        count = self.status.reject(kind)
        return Outcome(ScanVerdict(stamp_ns, ERROR, message, {"rejected": kind}),
                       self.throttled(kind, f"[{kind}] {message} ({count} rejected so far)"))

    def unpaired(self, source_stamp_ns: int, tolerance_ns: int) -> Outcome:
        """Pair mode: a source that no target within the tolerance will meet."""
        return self.rejected("unpaired", f"source at {source_stamp_ns * 1e-9:.3f} s has no target within "
                                         f"{tolerance_ns * 1e-9:.3f} s", source_stamp_ns)

    def admitted(self, warnings: list) -> list[str]:
        """Count the (kind, message) warnings of an admitted input; the log lines due."""
        lines = []
        for kind, message in warnings:
            count = self.status.warn(kind)
            lines += self.throttled(kind, f"[{kind}] {message} ({count} so far)")
        return lines

    def step(self, step: Any) -> Outcome:
        """A registered step (an ``AlignmentStep``): counted, its input warnings, WARN when flagged."""
        self.status.step_done(step)
        lines = self.admitted(step.warnings)
        if not step.accepted:
            lines += self.throttled("flagged", f"step at {step.stamp_ns * 1e-9:.3f} s flagged: {step.reason}")
        values = {"fitness": round(step.fitness, 4), "recovered": step.recovered, "origin": step.origin,
                  "effort": step.effort, "polishes": step.polishes, "map_restarted": step.map_restarted,
                  "warnings": "; ".join(f"[{kind}] {text}" for kind, text in step.warnings)}
        return Outcome(ScanVerdict(step.stamp_ns, OK if step.accepted else WARN, step.reason or "ok", values), lines)

    def vouched_late(self, stamp_ns: int) -> Outcome:
        """An earlier step, published flagged, that the node now vouches for (counted: ``vouched_late``)."""
        self.status.vouched_late_done()
        return Outcome(ScanVerdict(stamp_ns, OK, "vouched for late: the search beside the worker confirmed it",
                                   {"vouched_late": True}), [])

    def error(self, exc: BaseException, stamp_ns: Optional[int]) -> Outcome:
        """A scan whose processing raised (a bug to report): an ERROR verdict, so that no scan goes unreported."""
        name = type(exc).__name__
        message = f"registration failed: {name}: {exc}"
        with self._lock:
            first = name not in self._error_types
            self._error_types.add(name)
        error = message + "\n" + "".join(traceback.format_exception(exc)) if first else None
        return Outcome(ScanVerdict(stamp_ns, ERROR, message, {"error": name}), self.throttled("error", message), error)
