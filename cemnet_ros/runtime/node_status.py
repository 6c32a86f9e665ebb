"""What the node reports on /diagnostics, as plain code: counters, input and decoded rates, and the level.

Levels follow diagnostic_msgs/DiagnosticStatus (OK 0, WARN 1, ERROR 2). No input for ``input_timeout`` is a
WARN, for 3x that an ERROR (Autoware's "no input source" check); when publishers are matched on the input topic
but not one message has ever arrived, the message says so (the transport drops the clouds: the shipped DDS
profile fixes that, docs/node.md). New rejected inputs, drops, errors or flagged steps since the last report are
a WARN, and so are scans arriving for ``CLOCK_GRACE_S`` while the node's ROS time stays unset (use_sim_time
without /clock: every scan's stamp is then ahead of a clock that reads 0) and a standing warning (a condition that
lasts until the node restarts, e.g. an extrinsic ignored: ``warning_<kind>`` in the values). The reports name the
sensor in ``hardware_id``: the frame of its scans on the input topic (:meth:`NodeStatus.hardware_id`), so that two
odometry nodes on two sensors read apart in an aggregator or ``rqt_robot_monitor``.
"""
from __future__ import annotations

import collections
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Optional

OK, WARN, ERROR = 0, 1, 2
RATE_WINDOW_S = 5.0  # input rate over this many seconds
CLOCK_GRACE_S = 3.0  # scans for this long without a /clock (use_sim_time): a WARN
SILENT_HINT = ("large clouds need the shipped DDS profile on both sides: export FASTRTPS_DEFAULT_PROFILES_FILE="
               "<share>/cemnet_ros/config/fastdds_large_data.xml (docs/node.md: Large clouds)")


class _Rate:
    """Events per second over the last RATE_WINDOW_S (not thread-safe: NodeStatus locks)."""

    def __init__(self) -> None:
        self.times: collections.deque = collections.deque()

    def add(self, now: float) -> None:
        self.times.append(now)
        while self.times and self.times[0] < now - RATE_WINDOW_S:
            self.times.popleft()

    def per_second(self, now: float, span: float) -> float:
        recent = sum(1 for t in self.times if t >= now - RATE_WINDOW_S)
        return recent / span if span > 0 else 0.0


@dataclass
class Report:
    level: int
    message: str
    values: dict[str, Any] = field(default_factory=dict)
    hardware_id: str = ""


class NodeStatus:
    """Thread-safe counters of one node; :meth:`report` is called by the diagnostics timer."""

    def __init__(self, input_timeout: float, clock=time.monotonic, input_topic: str = "") -> None:
        self.input_timeout = float(input_timeout)
        self.input_topic = input_topic  # resolved: the scans' (sequential) or the sources' (pair mode)
        self._scan_frame = ""  # the frame_id of the last decoded input scan
        self._clock = clock
        self._lock = threading.Lock()
        self._started = clock()
        self._arrivals, self._decoded = _Rate(), _Rate()
        self.rejected: collections.Counter = collections.Counter()
        self.warned: collections.Counter = collections.Counter()  # admitted with a warning (decimated, ...)
        self.received = 0
        self._first_input: Optional[float] = None
        self.published = 0
        self.flagged = 0
        self.vouched_late = 0  # flagged steps the search beside the worker confirmed later
        self.recoveries = 0
        self.ready = False  # the engine has loaded
        self.last_step: Any = None
        self.standing: dict[str, str] = {}  # kind -> a warning that holds until the node restarts
        self._previous = (0, 0, 0, 0)  # rejected, drops, errors, flagged at the previous report

    def input_arrived(self) -> None:
        with self._lock:
            self.received += 1
            self._arrivals.add(self._clock())
            if self._first_input is None:
                self._first_input = self._arrivals.times[-1]

    def decoded(self) -> None:
        """The worker took a message out of the queue and decoded it."""
        with self._lock:
            self._decoded.add(self._clock())

    def scan_frame(self, frame_id: str) -> None:
        """The frame_id of an input scan (a source in pair mode), for :meth:`hardware_id`."""
        with self._lock:
            self._scan_frame = frame_id

    def hardware_id(self) -> str:
        """The sensor as the diagnostics name it: ``<frame_id of its scans> on <input topic>``, e.g. ``velodyne on
        /robot1/points``; the topic alone until a scan has been decoded (or when its frame_id is empty)."""
        with self._lock:
            frame = self._scan_frame
        return f"{frame} on {self.input_topic}" if frame else self.input_topic

    def warn(self, kind: str) -> int:
        """Count a scan admitted with a warning of ``kind``; its count so far."""
        with self._lock:
            self.warned[kind] += 1
            return self.warned[kind]

    def reject(self, kind: str) -> int:
        """Count a rejected input; its count so far."""
        with self._lock:
            self.rejected[kind] += 1
            return self.rejected[kind]

    def step_done(self, step: Any) -> None:
        with self._lock:
            self.last_step = step
            self.published += 1
            self.recoveries += int(step.recovered)
            self.flagged += int(not step.accepted)

    def vouched_late_done(self) -> None:
        with self._lock:
            self.vouched_late += 1

    def input_age(self) -> Optional[float]:
        """Seconds since the last input (None: none yet)."""
        with self._lock:
            return None if not self._arrivals.times else self._clock() - self._arrivals.times[-1]

    def stand(self, kind: str, message: str) -> None:
        """A warning every later report repeats (WARN, ``warning_<kind>`` in the values)."""
        with self._lock:
            self.standing[kind] = message

    def missing_clock(self, clock_unset: bool) -> Optional[str]:
        """Why the scans cannot be used while ``clock_unset`` (use_sim_time and no /clock yet), once they have
        arrived for CLOCK_GRACE_S; None otherwise."""
        with self._lock:
            first, now = self._first_input, self._clock()
        if not clock_unset or first is None or now - first < CLOCK_GRACE_S:
            return None
        return (f"use_sim_time is true but no /clock has arrived in {now - first:.0f} s of scans: ROS time is 0, "
                "so scans stamped by a sensor or a bag are refused as ahead of it (replay with 'ros2 bag play "
                "--clock', or set use_sim_time false)")

    def report(self, queue: Any, scale: Optional[float], publishers: int = 0, clock_unset: bool = False) -> Report:
        """The status now; ``queue`` is the worker's :class:`~cemnet_ros.runtime.worker.WorkerStats`,
        ``publishers`` the number matched on the input topic, ``clock_unset`` whether the node's ROS time is
        unset (use_sim_time and no /clock yet)."""
        missing_clock = self.missing_clock(clock_unset)
        with self._lock:
            now = self._clock()
            rejected, flagged, step, recoveries = dict(self.rejected), self.flagged, self.last_step, self.recoveries
            vouched_late = self.vouched_late
            warned, published, received = dict(self.warned), self.published, self.received
            standing = dict(self.standing)
            last = self._arrivals.times[-1] if self._arrivals.times else None
            span = min(RATE_WINDOW_S, now - self._started)
            rate, decoded_rate = self._arrivals.per_second(now, span), self._decoded.per_second(now, span)
            counts = (sum(rejected.values()), queue.drops, queue.errors, flagged)
            previous, self._previous = self._previous, counts
        age = now - (last if last is not None else self._started)
        level, message = self._level(counts, previous, age, publishers if received == 0 else 0)
        for warning in ([missing_clock] if missing_clock else []) + list(standing.values()):
            level, message = max(level, WARN), warning + ("" if message == "ok" else f"; {message}")
        values = {
            "input_age_s": "" if last is None else round(age, 3), "input_rate_hz": round(rate, 2),
            "decoded_rate_hz": round(decoded_rate, 2), "input_publishers": publishers, "received": received,
            "engine_ready": self.ready, "ros_time_unset": clock_unset,
            "queue_depth": queue.depth, "queue_drops": queue.drops,
            "processed": published, "errors": queue.errors,
            "latency_last_ms": round(queue.latency_last_s * 1e3, 1),
            "latency_mean_ms": round(queue.latency_mean_s * 1e3, 1),
            "latency_max_ms": round(queue.latency_max_s * 1e3, 1),
            "recoveries": recoveries, "flagged_steps": flagged, "vouched_late": vouched_late,
            "rejected_inputs": counts[0],
            "scale_m_per_unit": "" if scale is None else round(scale, 4),
        }
        for name in ("fitness", "accepted", "reason", "recovered", "recovery_reason", "degenerate"):
            value = "" if step is None else getattr(step, name)
            values["last_" + name] = round(value, 4) if isinstance(value, float) else value
        values.update({f"rejected_{kind}": count for kind, count in sorted(rejected.items())})
        values.update({f"warned_{kind}": count for kind, count in sorted(warned.items())})
        values.update({f"warning_{kind}": text for kind, text in sorted(standing.items())})
        return Report(level, message, values, self.hardware_id())

    def _level(self, counts: tuple, previous: tuple, age: float, silent_publishers: int) -> tuple[int, str]:
        """``silent_publishers``: matched on the input topic, not one message received from any of them."""
        problems = [label for label, c, p in zip(("rejected inputs", "dropped scans", "registration errors",
                                                   "flagged steps"), counts, previous) if c > p]
        level, message = (WARN, "new " + ", ".join(problems)) if problems else (OK, "ok")
        if not self.ready:
            level, message = max(level, WARN), "loading the engine; " + message
        silence = f"no input for {age:.1f} s"
        if silent_publishers:
            silence += f" although {silent_publishers} publisher(s) are matched: {SILENT_HINT}"
        if age > 3.0 * self.input_timeout:
            level, message = ERROR, silence
        elif age > self.input_timeout:
            level, message = max(level, WARN), silence
        return level, message
