"""The node's trajectory: every published pose kept in order, bounded by dropping the oldest, copies out."""
from __future__ import annotations

import threading
from types import SimpleNamespace

import numpy as np
import pytest

from cemnet_ros.runtime.trajectory_log import TrajectoryLog


def _pose(k: int) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = [k, 2.0 * k, -k]
    return T


def _step(k: int) -> SimpleNamespace:
    return SimpleNamespace(accepted=k % 3 != 0, degenerate=k % 5 == 0, recovered=k % 7 == 0, fitness=k / 100)


def test_poses_and_flags_come_back_in_order_across_growth():
    log = TrajectoryLog(max_poses=5000)
    for k in range(3000):  # past the first allocation (1024) twice
        log.append(10 * k, _pose(k), _step(k))
    kept = log.snapshot()
    assert len(log) == 3000 and kept.dropped == 0
    assert kept.stamps_ns.tolist() == [10 * k for k in range(3000)]
    np.testing.assert_array_equal(kept.poses, [_pose(k) for k in range(3000)])
    assert kept.accepted.tolist() == [k % 3 != 0 for k in range(3000)]
    assert kept.degenerate.tolist() == [k % 5 == 0 for k in range(3000)]
    assert kept.recovered.tolist() == [k % 7 == 0 for k in range(3000)]
    np.testing.assert_allclose(kept.fitness, np.arange(3000) / 100)
    assert log.snapshot(last=2).stamps_ns.tolist() == [29980, 29990]


def test_the_bound_drops_the_oldest_and_counts_them():
    log = TrajectoryLog(max_poses=100)
    for k in range(250):
        log.append(k, _pose(k), _step(k))
    kept = log.snapshot()
    assert len(log) == 100 and kept.dropped == 150
    assert kept.stamps_ns.tolist() == list(range(150, 250))
    np.testing.assert_array_equal(kept.poses[0], _pose(150))
    assert log.snapshot(last=3).stamps_ns.tolist() == [247, 248, 249]
    with pytest.raises(ValueError, match=">= 1"):
        TrajectoryLog(0)


def test_a_snapshot_is_a_copy_and_reading_while_appending_is_safe():
    log = TrajectoryLog(max_poses=50)
    log.append(0, _pose(0), _step(0))
    first = log.snapshot()
    first.poses[0, 0, 3] = 99.0
    assert log.snapshot().poses[0, 0, 3] == 0.0
    stop, seen = threading.Event(), []

    def reader():
        while not stop.is_set():
            kept = log.snapshot()
            seen.append(bool(np.all(np.diff(kept.stamps_ns) == 1)))  # never a torn, out-of-order copy

    thread = threading.Thread(target=reader)
    thread.start()
    for k in range(1, 5000):
        log.append(k, _pose(k), _step(k))
    stop.set()
    thread.join()
    assert seen and all(seen)
