"""Pair mode's matching of source scans to target clouds by stamp (no ROS: the node only feeds it)."""
from __future__ import annotations

import collections
import threading
from typing import Any, Generic, Optional, Protocol, TypeVar


class Stamped(Protocol):
    stamp_ns: int


S = TypeVar("S", bound=Stamped)


class PairMatcher(Generic[S]):
    """Sources wait for a target within ``tolerance_ns`` of their stamp (0: always the latest target).

    At most ``pending_limit`` sources wait; a source whose chance has passed (a newer target arrived beyond the
    tolerance) or that is pushed out is returned as unpaired, so the node can count and report it.
    """

    def __init__(self, tolerance_ns: int, pending_limit: int, target_depth: int) -> None:
        self.tolerance_ns = int(tolerance_ns)
        self._pending_limit = max(int(pending_limit), 1)
        self._sources: collections.deque = collections.deque()
        self._targets: collections.deque = collections.deque(maxlen=max(int(target_depth), 1))
        self._lock = threading.Lock()

    def add_source(self, scan: S) -> tuple[list[tuple[S, S]], list[S]]:
        with self._lock:
            self._sources.append(scan)
            return self._match()

    def add_target(self, scan: S) -> tuple[list[tuple[S, S]], list[S]]:
        with self._lock:
            self._targets.append(scan)
            return self._match()

    def _match(self) -> tuple[list[tuple[Any, Any]], list[Any]]:
        """(ready (source, target) pairs, unpaired sources)."""
        ready, unpaired = [], []
        for source in list(self._sources):
            target = self._nearest_target(source.stamp_ns)
            if target is not None:
                ready.append((source, target))
                self._sources.remove(source)
            elif self._targets and self._targets[-1].stamp_ns > source.stamp_ns + self.tolerance_ns:
                unpaired.append(source)
                self._sources.remove(source)
        while len(self._sources) > self._pending_limit:
            unpaired.append(self._sources.popleft())
        return ready, unpaired

    def _nearest_target(self, stamp_ns: int) -> Optional[Any]:
        if not self._targets:
            return None
        if self.tolerance_ns == 0:
            return self._targets[-1]
        best = min(self._targets, key=lambda t: abs(t.stamp_ns - stamp_ns))
        return best if abs(best.stamp_ns - stamp_ns) <= self.tolerance_ns else None
