"""align_lifecycle_node through rclpy's lifecycle services: configure loads the engine (no subscription yet) while
the parameter services keep answering, activate subscribes and publishes, deactivate stops and keeps the trajectory,
cleanup drops it and a new configure loads it again; a configure that cannot load fails and leaves the node
unconfigured."""
from __future__ import annotations

import os
import threading

import numpy as np
import pytest

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # read when the DDS participant is created

import rclpy  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from lifecycle_msgs.msg import Transition, TransitionEvent  # noqa: E402
from lifecycle_msgs.srv import ChangeState, GetState  # noqa: E402
from nav_msgs.msg import Odometry  # noqa: E402
from node_harness import (  # noqa: E402
    EXTRINSIC,
    FIRST_TIMEOUT,
    HARNESS_PARAMETERS,
    POSES,
    StandInBuffer,
    pose_of,
    scan_msg,
    transform,
    wait_for,
)
from rcl_interfaces.srv import GetParameters  # noqa: E402
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import PointCloud2  # noqa: E402

from benchmarks.metrics import relative_error  # noqa: E402
from cemnet_ros.ros import engine_load  # noqa: E402
from cemnet_ros.ros.align_lifecycle_node import AlignLifecycleNode  # noqa: E402

pytestmark = pytest.mark.dds


class Managed:
    """An align_lifecycle_node and a probe (lifecycle clients, the scan publisher, an odometry subscriber)."""

    def __init__(self, context, namespace, overrides=None):
        params = [Parameter(k, value=v) for k, v in {**HARNESS_PARAMETERS, **(overrides or {})}.items()]
        self.node = AlignLifecycleNode(context=context, namespace=namespace, parameter_overrides=params)
        self.probe = rclpy.create_node("lifecycle_probe", namespace=namespace, context=context)
        ns = f"/{namespace}/align_node"
        self.change = self.probe.create_client(ChangeState, f"{ns}/change_state")
        self.get = self.probe.create_client(GetState, f"{ns}/get_state")
        self.get_parameters = self.probe.create_client(GetParameters, f"{ns}/get_parameters")
        self.transitions = []  # the goal states of ~/transition_event, in order
        self.probe.create_subscription(TransitionEvent, f"{ns}/transition_event",
                                       lambda msg: self.transitions.append(msg.goal_state.label), 10)
        self.points = self.probe.create_publisher(PointCloud2, f"/{namespace}/points", 10)
        self.odometry, self.diagnostics = [], []
        self.probe.create_subscription(Odometry, f"{ns}/odometry", self.odometry.append, 50)
        self.probe.create_subscription(DiagnosticArray, "/diagnostics", lambda msg: self.diagnostics.extend(
            status for status in msg.status if status.name == f"{ns}: alignment"), 50)
        self.executor = MultiThreadedExecutor(num_threads=2, context=context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.probe)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()
        assert self.change.wait_for_service(10.0) and self.get.wait_for_service(10.0)

    def _call(self, client, request, timeout):
        future = client.call_async(request)
        assert wait_for(future.done, timeout), "no answer from the lifecycle service"
        return future.result()

    def state(self):
        return self._call(self.get, GetState.Request(), 10.0).current_state.label

    def transition(self, transition_id, timeout=FIRST_TIMEOUT):
        return self._call(self.change, ChangeState.Request(transition=Transition(id=transition_id)), timeout).success

    def subscribed(self):
        return self.points.get_subscription_count() > 0

    def close(self):
        self.executor.shutdown()
        self.thread.join(10)
        self.node.destroy_node()
        self.probe.destroy_node()


@pytest.fixture
def managed_factory(context, request):
    made = []

    def make(overrides=None):
        made.append(Managed(context, f"lc{len(made)}_{request.node.name}"[:50].lower(), overrides))
        return made[-1]

    yield make
    for managed in made:
        managed.close()


def _send(managed, k, expect_output=True):
    count = len(managed.odometry)
    managed.points.publish(scan_msg(k))
    if expect_output:
        assert wait_for(lambda: len(managed.odometry) > count, FIRST_TIMEOUT), f"no odometry for scan {k}"
        return managed.odometry[-1]
    return None


def test_configure_activate_deactivate_cleanup(managed_factory):
    managed = managed_factory()
    assert managed.state() == "unconfigured" and not managed.subscribed()
    assert managed.transition(Transition.TRANSITION_CONFIGURE)
    assert managed.state() == "inactive" and not managed.subscribed()
    assert managed.transition(Transition.TRANSITION_ACTIVATE)
    assert managed.state() == "active" and wait_for(managed.subscribed, 10.0)
    outputs = [_send(managed, k) for k in range(2)]
    assert managed.transition(Transition.TRANSITION_DEACTIVATE)
    assert managed.state() == "inactive" and wait_for(lambda: not managed.subscribed(), 10.0)
    _send(managed, 2, expect_output=False)
    assert not wait_for(lambda: len(managed.odometry) > 2, 2.0), "an inactive node published"
    assert managed.transition(Transition.TRANSITION_ACTIVATE) and wait_for(managed.subscribed, 10.0)
    outputs.append(_send(managed, 3))  # the trajectory continues: scan 3 from scan 1
    for k, odom in zip((0, 1, 3), outputs):
        trans_err, rot_err = relative_error(pose_of(odom), np.linalg.inv(POSES[0]) @ POSES[k])
        assert trans_err < 0.03 * k + 0.01 and rot_err < 0.1 * k + 0.01, (k, trans_err, rot_err)
    assert managed.transition(Transition.TRANSITION_DEACTIVATE)
    assert managed.transition(Transition.TRANSITION_CLEANUP)
    assert managed.state() == "unconfigured" and not managed.subscribed()
    assert managed.transition(Transition.TRANSITION_CONFIGURE)  # the engine was dropped: loaded again
    assert managed.state() == "inactive"


def test_parameter_requests_are_answered_while_configure_waits_for_the_engine(managed_factory, monkeypatch):
    """rclpy's transitions are synchronous: configure holds its executor thread until the engine has loaded. The
    lifecycle services have their own callback group, so the parameter services still answer meanwhile."""
    engine_may_load = threading.Event()
    load = engine_load.counted_load

    def held_back(session):
        engine_may_load.wait()
        return load(session)

    monkeypatch.setattr(engine_load, "counted_load", held_back)  # the load started at construction waits
    managed = managed_factory()
    try:
        configure = managed.change.call_async(ChangeState.Request(
            transition=Transition(id=Transition.TRANSITION_CONFIGURE)))
        assert wait_for(lambda: "configuring" in managed.transitions, 10.0), managed.transitions
        answer = managed._call(managed.get_parameters, GetParameters.Request(names=["input_topic"]), 10.0)
        assert [value.string_value for value in answer.values] == ["points"]
        assert not configure.done() and managed.transitions == ["configuring"]
    finally:
        engine_may_load.set()
    assert wait_for(configure.done, FIRST_TIMEOUT) and configure.result().success
    assert managed.state() == "inactive"


def test_a_configure_that_cannot_load_fails_and_stays_unconfigured(managed_factory):
    managed = managed_factory({"tracking.centre": "network", "registration.weights": "/nonexistent/w.npz"})
    assert not managed.transition(Transition.TRANSITION_CONFIGURE)
    assert managed.state() == "unconfigured" and not managed.subscribed()


def test_an_ignored_extrinsic_is_still_reported_after_a_reactivation(managed_factory):
    managed = managed_factory()
    assert managed.transition(Transition.TRANSITION_CONFIGURE) and managed.transition(Transition.TRANSITION_ACTIVATE)
    managed.node._alignment.tf_buffer = buffer = StandInBuffer()
    assert wait_for(managed.subscribed, 10.0)
    _send(managed, 0)
    buffer.transform = transform(EXTRINSIC)  # after the first output: ignored
    _send(managed, 1)
    assert managed.transition(Transition.TRANSITION_DEACTIVATE) and managed.transition(Transition.TRANSITION_ACTIVATE)
    count = len(managed.diagnostics)
    assert wait_for(lambda: len(managed.diagnostics) > count, 5.0)
    values = {kv.key: kv.value for kv in managed.diagnostics[-1].values}
    assert "arrived after the first output" in values.get("warning_extrinsic", ""), values
