"""align_node as a process: Ctrl-C ends it cleanly, also when more SIGINTs arrive during its teardown (a terminal
and ``ros2 launch`` both send one)."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest
from ros_cli import kill_group, start


@pytest.mark.dds
@pytest.mark.parametrize("interrupts", [1, 3])
def test_repeated_sigint_ends_the_node_with_status_0_and_no_traceback(interrupts):
    def after_engine_ready(node, output):
        assert output.wait_for("engine ready", 120.0), output.text()
        for _ in range(interrupts):
            node.send_signal(signal.SIGINT)
            time.sleep(0.02)

    _assert_interrupted_cleanly([sys.executable, "-m", "cemnet_ros.ros.align_node"], 220 + interrupts,
                                after_engine_ready)


@pytest.mark.dds
@pytest.mark.parametrize("after_s", [0.2, 0.4])
def test_sigint_while_the_console_script_still_imports_ends_it_with_status_0_and_no_traceback(after_s):
    """The modules take ~0.4-0.6 s to import; a launch stopped at once interrupted that with a traceback."""
    script = os.path.join(os.path.dirname(sys.executable), "align_node")
    if not os.path.exists(script):
        pytest.skip("the align_node console script is not installed beside this interpreter")

    def while_importing(node, output):
        time.sleep(after_s)
        node.send_signal(signal.SIGINT)

    _assert_interrupted_cleanly([script], 224 + round(10 * after_s), while_importing)


MAKE_NODE_AFTER_SIGINT = """
import sys
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from cemnet_ros.ros.process import run

class SignalledWhileSpinning(SingleThreadedExecutor):
    def spin_once(self, timeout_sec=None):
        rclpy.try_shutdown()  # a SIGTERM's handler, between the loop's check and the wait
        super().spin_once(timeout_sec=timeout_sec)  # raises: the context is no longer valid

def make_node():
    if sys.argv[1] == "interrupted":
        rclpy.try_shutdown()  # what rclpy's SIGINT handler does to the context
        return Node("made_after_sigint")  # raises: the context is no longer valid
    if sys.argv[1] == "spinning":
        node = Node("signalled_while_spinning")
        node.fatal_error = None
        return node
    raise RuntimeError("a real failure while making the node")

run(make_node, "probe", executor=SignalledWhileSpinning)
print("ended")
"""


@pytest.mark.dds
def test_a_signal_while_the_node_is_made_or_spins_ends_it_with_status_0_and_a_real_error_still_raises():
    """A Ctrl-C after rclpy.init but before the node exists, or a signal while it spins (rclpy's handler shuts the
    context down, so making the node or its wait fails): status 0, no traceback. The same failure with the context
    still valid is a real error."""
    env = {**os.environ, "ROS_DOMAIN_ID": "229", "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    interrupted = subprocess.run([sys.executable, "-c", MAKE_NODE_AFTER_SIGINT, "interrupted"], env=env,
                                 capture_output=True, text=True, timeout=60)
    assert interrupted.returncode == 0 and "Traceback" not in interrupted.stderr, interrupted.stderr
    assert interrupted.stdout.strip() == "ended"
    spinning = subprocess.run([sys.executable, "-c", MAKE_NODE_AFTER_SIGINT, "spinning"], env=env,
                              capture_output=True, text=True, timeout=60)
    assert spinning.returncode == 0 and "Traceback" not in spinning.stderr, spinning.stderr
    assert spinning.stdout.strip() == "ended"
    failing = subprocess.run([sys.executable, "-c", MAKE_NODE_AFTER_SIGINT, "failing"], env=env,
                             capture_output=True, text=True, timeout=60)
    assert failing.returncode != 0 and "a real failure while making the node" in failing.stderr


def _assert_interrupted_cleanly(command, domain_id, interrupt):
    """Start ``command`` on its own ROS domain, let ``interrupt(node, output)`` send its SIGINTs, and require that
    the process ends with status 0 and no traceback."""
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "PYTHONUNBUFFERED": "1"}
    node, output = start(command, env)
    try:
        interrupt(node, output)
        node.wait(timeout=60)
    finally:
        kill_group(node)
    log = output.text(timeout=10.0)
    assert node.returncode == 0, log
    assert "Traceback" not in log and "KeyboardInterrupt" not in log, log
