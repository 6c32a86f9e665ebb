"""A bounded queue drained by one worker thread, so callers (ROS callbacks) never wait on registration.

When the queue is full the OLDEST item is dropped: for odometry the newest scan is the one worth aligning.
"""
from __future__ import annotations

import collections
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Optional


@dataclass
class WorkerStats:
    """A consistent snapshot of the worker's counters (latency = submit -> handler done, seconds)."""

    depth: int
    drops: int
    processed: int
    errors: int
    latency_last_s: float
    latency_mean_s: float
    latency_max_s: float


class BoundedWorker:
    """Runs ``handler(item)`` for submitted items on one background thread, queue bounded by ``maxsize``.

    Exceptions raised by the handler are counted and passed to ``on_error(item, exc)``; the thread goes on.
    """

    def __init__(self, handler: Callable[[Any], None], maxsize: int = 2,
                 on_error: Optional[Callable[[Any, BaseException], None]] = None, name: str = "worker") -> None:
        if maxsize < 1:
            raise ValueError("maxsize must be >= 1")
        self._handler = handler
        self._on_error = on_error
        self._queue: collections.deque = collections.deque()
        self._maxsize = maxsize
        self._cond = threading.Condition()
        self._closed = False
        self._busy = False
        self._drops = self._processed = self._errors = 0
        self._lat_last = self._lat_sum = self._lat_max = 0.0
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, item: Any) -> bool:
        """Queue ``item``; returns False when an older item had to be dropped to make room (or when closed)."""
        with self._cond:
            if self._closed:
                return False
            dropped = len(self._queue) >= self._maxsize
            if dropped:
                self._queue.popleft()
                self._drops += 1
            self._queue.append((time.monotonic(), item))
            self._cond.notify()
            return not dropped

    def stats(self) -> WorkerStats:
        with self._cond:
            n = self._processed + self._errors
            return WorkerStats(depth=len(self._queue), drops=self._drops, processed=self._processed,
                               errors=self._errors, latency_last_s=self._lat_last,
                               latency_mean_s=self._lat_sum / n if n else 0.0, latency_max_s=self._lat_max)

    def wait_idle(self, timeout: float) -> bool:
        """Block until the queue is empty and no item is running; False on timeout."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._queue or self._busy:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self._cond.wait(remaining)
            return True

    def close(self, timeout: float = 5.0) -> bool:
        """Discard queued items, let the running one finish, stop the thread; False if it did not stop in time."""
        with self._cond:
            self._closed = True
            self._queue.clear()
            self._cond.notify_all()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout)
        return not self._thread.is_alive()

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._queue and not self._closed:
                    self._cond.wait()
                if self._closed:
                    return
                submitted, item = self._queue.popleft()
                self._busy = True
            ok = True
            try:
                self._handler(item)
            except Exception as exc:  # noqa: BLE001 - a bad item must not kill the worker
                ok = False
                if self._on_error is not None:
                    try:
                        self._on_error(item, exc)
                    except Exception:  # noqa: BLE001
                        pass
            latency = time.monotonic() - submitted
            with self._cond:
                self._busy = False
                if ok:
                    self._processed += 1
                else:
                    self._errors += 1
                self._lat_last = latency
                self._lat_sum += latency
                self._lat_max = max(self._lat_max, latency)
                self._cond.notify_all()
