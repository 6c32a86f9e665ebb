"""The map's unvouched scans and the second worker that checks them (pipeline/unvouched.py, side_search.py)."""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.side_search import SideSearch
from cemnet_ros.pipeline.steps.motion import ConstantVelocity
from cemnet_ros.pipeline.unvouched import Check, Unvouched, UnvouchedScan


def finished(worker, timeout_s=10.0):
    deadline = time.monotonic() + timeout_s
    while (result := worker.finished()) is None:
        assert time.monotonic() < deadline
        time.sleep(0.001)
    return result


def scan(stamp_ns, checked_by=None):
    check = None if checked_by is None else Check(VoxelMap(1.0), None, checked_by)
    return UnvouchedScan(stamp_ns, None, np.eye(4), check)


def test_the_side_search_runs_one_registration_on_another_thread_and_hands_it_back_once():
    side, threads = SideSearch(), []
    side.start("key", lambda: threads.append(threading.get_ident()) or "registered")
    assert side.busy and finished(side) == ("key", "registered")
    assert threads and threads[0] != threading.get_ident() and not side.busy and side.finished() is None


def test_a_forgotten_registration_is_dropped_and_an_error_in_one_is_raised_to_the_worker():
    side = SideSearch()
    side.start("old", lambda: time.sleep(0.05) or "late")
    side.forget()
    assert not side.busy and side.finished() is None
    side.start("new", lambda: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        finished(side)


def test_checks_run_oldest_first_and_a_confirmation_vouches_up_to_the_next_scan_with_a_check_of_its_own():
    checked = []
    unvouched = Unvouched()
    unvouched.add(scan(1, lambda: checked.append(1) or "one"))
    unvouched.add(scan(2))  # stood on its own evidence, flagged for the map's sake
    unvouched.add(scan(3, lambda: checked.append(3) or "three"))
    unvouched.add(scan(4))
    unvouched.start_check()
    first, registered = finished(unvouched)
    assert (first.stamp_ns, registered, checked) == (1, "one", [1])
    assert unvouched.vouched(first) == [1, 2] and len(unvouched) == 2 and unvouched.oldest.stamp_ns == 3
    unvouched.start_check()
    third, _ = finished(unvouched)
    assert unvouched.vouched(third) == [3, 4] and len(unvouched) == 0


def test_a_scan_that_owed_the_search_vouches_for_itself_alone_and_its_followers_leave_flagged():
    unvouched = Unvouched()
    owed = UnvouchedScan(1, None, np.eye(4), Check(VoxelMap(1.0), None, lambda: "one"), owed_search=True)
    unvouched.add(owed)
    unvouched.add(scan(2))  # stood on its own evidence, without the search the scan before it owed
    unvouched.add(scan(3, lambda: "three"))
    unvouched.start_check()
    first, _ = finished(unvouched)
    assert unvouched.vouched(first) == [1]
    assert len(unvouched) == 1 and unvouched.oldest.stamp_ns == 3  # scan 2 left the list, not vouched for


def test_the_first_unvouched_scan_is_one_with_a_check_of_its_own():
    with pytest.raises(AssertionError):
        Unvouched().add(scan(1))


def test_a_map_snapshot_keeps_what_it_held_while_the_map_grows():
    rng = np.random.default_rng(0)
    live = VoxelMap(0.5)
    live.update(rng.uniform(0, 5, (500, 3)), np.zeros(3))
    size = len(live)
    snapshot = live.snapshot()
    live.update(rng.uniform(10, 15, (500, 3)), np.full(3, 10.0))
    assert len(live) > size and len(snapshot) == size
    far = np.full((1, 3), 12.5)
    assert np.isinf(snapshot.nearest(far, 1.0)[0][0]) and np.isfinite(live.nearest(far, 1.0)[0][0])


def test_a_trajectory_moved_by_a_correction_keeps_its_motion():
    motion = ConstantVelocity()
    step = np.eye(4)
    step[:3, 3] = (1.0, 0.0, 0.0)
    motion.update(np.eye(4), 0)
    motion.update(step, 100)
    before = motion.predict_relative(200)
    correction = np.eye(4)
    correction[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    motion.moved(correction)
    np.testing.assert_allclose(motion.predict_relative(200), before, atol=1e-12)
    np.testing.assert_allclose(motion.last_pose, correction @ step, atol=1e-12)
