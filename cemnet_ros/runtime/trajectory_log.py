"""The poses a node published, kept for ``~/save_trajectory`` and ``~/path``: bounded, the oldest dropped first.

Each entry is one processed scan, accepted or flagged alike (what ``~/odometry`` and ``/tf`` carried): its stamp,
the base's pose in the output frame (3x4, float64) and the step's flags. 115 bytes a pose in numpy arrays that
double as they fill, up to ``max_poses`` (the ``trajectory_max_poses`` parameter; at 10 Hz 36 000 poses, 4 MB,
an hour); beyond it the oldest pose makes room (:attr:`TrajectoryLog.dropped` counts them).
"""
from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

BYTES_PER_POSE = 8 + 96 + 8 + 3  # stamp, 3x4 pose, fitness, three flags


@dataclass
class Trajectory:
    """A copy of the kept poses, oldest first."""

    stamps_ns: np.ndarray  # (n,) int64
    poses: np.ndarray  # (n, 4, 4) the base in the output frame
    accepted: np.ndarray  # (n,) bool: the node vouches for the step
    degenerate: np.ndarray  # (n,) bool: a direction was unconstrained (flagged, the pose used)
    recovered: np.ndarray  # (n,) bool: the step ran the global search
    fitness: np.ndarray  # (n,) float64
    dropped: int  # older poses dropped for the bound


_FLAGS = ("accepted", "degenerate", "recovered")


def _arrays(capacity: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Stamps, 3x4 poses, fitness and flags for ``capacity`` poses."""
    return (np.zeros(capacity, dtype=np.int64), np.zeros((capacity, 3, 4)), np.zeros(capacity),
            np.zeros((capacity, len(_FLAGS)), dtype=bool))


class TrajectoryLog:
    """Thread-safe: the worker appends, the services and the ~/path timer read."""

    def __init__(self, max_poses: int) -> None:
        if max_poses < 1:
            raise ValueError(f"max_poses must be >= 1, not {max_poses}")
        self.max_poses = int(max_poses)
        self.dropped = 0
        self._lock = threading.Lock()
        self._start = 0  # index of the oldest pose once the arrays are full (a ring)
        self._count = 0
        self._stamps, self._poses, self._fitness, self._flags = _arrays(min(1024, self.max_poses))

    def _grow(self, capacity: int) -> None:
        """Larger arrays holding the kept poses (only before the ring wraps: they are the first ``_count``)."""
        arrays = _arrays(capacity)
        for new, kept in zip(arrays, (self._stamps, self._poses, self._fitness, self._flags)):
            new[:self._count] = kept[:self._count]
        self._stamps, self._poses, self._fitness, self._flags = arrays

    def __len__(self) -> int:
        with self._lock:
            return self._count

    def append(self, stamp_ns: int, T: np.ndarray, step: object) -> None:
        """One published pose (4x4) at ``stamp_ns``; ``step`` gives ``accepted``, ``degenerate``, ``recovered``
        and ``fitness`` (an AlignmentStep)."""
        with self._lock:
            capacity = len(self._stamps)
            if self._count == capacity and capacity < self.max_poses:
                self._grow(min(2 * capacity, self.max_poses))
                capacity = len(self._stamps)
            if self._count < capacity:
                k = self._count
                self._count += 1
            else:  # full: overwrite the oldest
                k = self._start
                self._start = (self._start + 1) % capacity
                self.dropped += 1
            self._stamps[k] = stamp_ns
            self._poses[k] = np.asarray(T, dtype=np.float64)[:3, :]
            self._fitness[k] = float(getattr(step, "fitness"))
            self._flags[k] = [bool(getattr(step, name)) for name in _FLAGS]

    def snapshot(self, last: int = 0) -> Trajectory:
        """The kept poses, oldest first; ``last`` > 0: only the newest ``last`` of them."""
        with self._lock:
            order = (self._start + np.arange(self._count)) % len(self._stamps)
            if last > 0:
                order = order[-last:]
            poses = np.tile(np.eye(4), (len(order), 1, 1))
            poses[:, :3, :] = self._poses[order]
            flags = self._flags[order]
            return Trajectory(self._stamps[order], poses, flags[:, 0], flags[:, 1], flags[:, 2],
                              self._fitness[order], self.dropped)
