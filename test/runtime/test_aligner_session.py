"""The node's aligner session without DDS: loading, requests between scans, step outputs, the map in odom."""
from __future__ import annotations

import threading
from types import SimpleNamespace

import numpy as np
import pytest

from cemnet_ros.core.geometry import apply_transform
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.ros.node_config import NodeConfig
from cemnet_ros.runtime.aligner_session import AlignerSession
from cemnet_ros.runtime.extrinsic import BaseFrame, pose_from_xyz_rpy
from cemnet_ros.runtime.odometry_output import aligned_points

T_BASE_SENSOR = pose_from_xyz_rpy((0.3, 0.0, 1.2, 0.0, 0.05, 0.3))
MOTION = pose_from_xyz_rpy((0.5, 0.02, 0.0, 0.0, 0.0, 0.04))  # the sensor's motion per scan


class FakeAligner:
    """Moves the sensor by MOTION per scan and records what the session asked of it."""

    def __init__(self, config):
        self.pose, self.calls, self.scale = np.eye(4), [], 0.25
        self.flag_stamps: set = set()  # steps at these stamps are flagged (and "recovered")
        self.local_map = SimpleNamespace(points=np.array([[1.0, 2.0, 3.0], [0.0, 0.0, 0.0]]), empty=lambda: False)

    def reset(self, T_odom_sensor):
        self.calls.append(("reset", T_odom_sensor.copy()))
        self.pose = T_odom_sensor.copy()

    def request_recovery(self):
        self.calls.append(("recovery",))

    period_s = 0.1  # the usual time between the stamps

    def process(self, points, stamp_ns, times, *, frame_id, now_ns, effort, budget_s):
        self.calls.append(("process", stamp_ns, frame_id, now_ns, effort, budget_s))
        relative = np.linalg.inv(self.pose) @ (self.pose @ MOTION)
        self.pose = self.pose @ MOTION
        flagged = stamp_ns in self.flag_stamps
        return SimpleNamespace(stamp_ns=stamp_ns, pose=self.pose.copy(), relative=relative, accepted=not flagged,
                               covariance=np.eye(6) * 1e-4, fitness=0.9, degenerate=False, recovered=flagged)


def _session(make=FakeAligner):
    return AlignerSession(AlignerConfig(), NodeConfig(), BaseFrame(T_BASE_SENSOR), make_aligner=make)


def _scan(stamp_ns):
    return SimpleNamespace(points=np.zeros((10, 3)), stamp_ns=stamp_ns, times=None)


def test_a_failed_load_is_fatal_and_releases_the_waiting_worker():
    def broken(config):
        raise OSError("weights file truncated\nsecond line")

    session, raised = _session(broken), []

    def worker():
        with pytest.raises(RuntimeError, match="did not load") as info:
            session.begin_scan()
        raised.append(info.value)

    waiting = threading.Thread(target=worker)
    waiting.start()
    assert session.load() is None
    waiting.join(5)
    assert not waiting.is_alive() and len(raised) == 1
    assert session.fatal_error == "the engine did not load: OSError: weights file truncated"
    assert session.scale is None and session.map_in_odom() is None


def test_steps_publish_the_base_motion_with_the_twist_over_the_stamp_gap():
    session = _session()
    assert session.load() >= 0
    session.begin_scan()
    first = session.process(_scan(1_000_000_000), "lidar", 5)
    session.begin_scan()
    second = session.process(_scan(1_100_000_000), "lidar", 6)
    assert session.scale == 0.25 and session._aligner.calls[0] == ("process", 1_000_000_000, "lidar", 5, 1.0, None)
    assert first.out.twist_known is False and second.out.twist_known
    base_motion = T_BASE_SENSOR @ MOTION @ np.linalg.inv(T_BASE_SENSOR)
    np.testing.assert_allclose(second.out.linear, base_motion[:3, 3] / 0.1, atol=1e-9)
    np.testing.assert_allclose(second.T_odom_sensor, second.out.T_odom_base @ T_BASE_SENSOR, atol=1e-12)
    np.testing.assert_allclose(second.out.T_odom_base, base_motion @ base_motion, atol=1e-9)


def test_a_live_scan_gets_the_scan_budget_and_one_that_starts_behind_newer_ones_the_behind_effort():
    session = _session()
    session.load()
    arrivals = ((1_000_000_000, 0, None), (1_100_000_000, 3, None), (1_200_000_000, 0, 0.05),
                (1_300_000_000, None, 0.05))
    for stamp_ns, backlog, period_s in arrivals:
        session.begin_scan()
        session.process(_scan(stamp_ns), "lidar", None, backlog, period_s)
    efforts = [call[-2] for call in session._aligner.calls]
    budgets = [call[-1] for call in session._aligner.calls]
    node = NodeConfig()
    assert efforts == [1.0, node.behind_effort, 1.0, 1.0] and node.behind_effort < 1.0
    # the arrivals' period where the caller measured it, else the stamps'; offline (no backlog) no bound
    assert budgets[:3] == pytest.approx([node.scan_budget * 0.1] * 2 + [node.scan_budget * 0.05])
    assert budgets[3] is None


def test_requests_wait_for_the_next_scan_and_set_pose_waits_for_the_aligner():
    session = _session()
    T_odom_base = pose_from_xyz_rpy((4.0, -1.0, 0.0, 0.0, 0.0, 1.0))
    session.set_pose(T_odom_base)  # before the aligner exists: carried out before the first scan
    session.load()
    session.request("reset")
    session.request("relocalize")
    aligner = session._aligner
    assert aligner.calls == []
    session.begin_scan()
    kinds = [call[0] for call in aligner.calls]
    assert kinds == ["reset", "reset", "recovery"]  # reset (pose kept), then the pose set, then the search
    np.testing.assert_allclose(session.base.pose(aligner.pose), T_odom_base, atol=1e-12)
    session.begin_scan()
    assert len(aligner.calls) == 3  # each request once
    session.set_pose(np.eye(4))  # loaded: now, between two scans
    np.testing.assert_allclose(aligner.pose, np.eye(4), atol=1e-12)


def test_the_map_is_read_in_odom_and_aligned_points_are_thinned_on_request():
    session = _session()
    session.load()
    np.testing.assert_allclose(session.map_in_odom(), apply_transform(T_BASE_SENSOR, session._aligner.local_map.points))
    session._aligner.local_map = SimpleNamespace(points=np.zeros((0, 3)), empty=lambda: True)
    assert session.map_in_odom() is None
    points = np.random.default_rng(0).uniform(0, 1, (2000, 3))
    np.testing.assert_allclose(aligned_points(points, T_BASE_SENSOR, 0.0), apply_transform(T_BASE_SENSOR, points))
    in_odom = apply_transform(T_BASE_SENSOR, points)
    thinned = aligned_points(points, T_BASE_SENSOR, 0.5)  # one point per 0.5 m voxel, in odom
    assert len(thinned) == len(np.unique(np.floor(in_odom / 0.5), axis=0)) > 1
    assert np.all((thinned.min(axis=0) >= in_odom.min(axis=0)) & (thinned.max(axis=0) <= in_odom.max(axis=0)))


def test_every_published_pose_joins_the_trajectory_flagged_ones_too():
    session = _session()
    session.load()
    session._aligner.flag_stamps = {1_200_000_000}
    results = [session.process(_scan(1_000_000_000 + k * 100_000_000), "lidar", None) for k in range(4)]
    kept = session.trajectory.snapshot()
    assert kept.stamps_ns.tolist() == [1_000_000_000 + k * 100_000_000 for k in range(4)]
    np.testing.assert_array_equal(kept.poses, [r.out.T_odom_base for r in results])  # the base's, as published
    assert kept.accepted.tolist() == [True, True, False, True] and kept.recovered.tolist()[2]
