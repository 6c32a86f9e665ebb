"""align_node as a process: Ctrl-C ends it cleanly, also when more SIGINTs arrive during its teardown (a terminal
and ``ros2 launch`` both send one)."""
from __future__ import annotations

import os
import signal
import sys
import time

import pytest
from ros_cli import kill_group, start


@pytest.mark.dds
@pytest.mark.parametrize("interrupts", [1, 3])
def test_repeated_sigint_ends_the_node_with_status_0_and_no_traceback(interrupts):
    env = {**os.environ, "ROS_DOMAIN_ID": str(220 + interrupts), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "PYTHONUNBUFFERED": "1"}
    node, output = start([sys.executable, "-m", "cemnet_ros.ros.align_node"], env)
    try:
        assert output.wait_for("engine ready", 120.0), output.text()
        for _ in range(interrupts):
            node.send_signal(signal.SIGINT)
            time.sleep(0.02)
        node.wait(timeout=60)
    finally:
        kill_group(node)
    log = output.text(timeout=10.0)
    assert node.returncode == 0, log
    assert "Traceback" not in log and "KeyboardInterrupt" not in log, log


@pytest.mark.dds
@pytest.mark.parametrize("after_s", [0.2, 0.4])
def test_sigint_while_the_console_script_still_imports_ends_it_with_status_0_and_no_traceback(after_s):
    """The modules take ~0.4-0.6 s to import; a launch stopped at once interrupted that with a traceback."""
    script = os.path.join(os.path.dirname(sys.executable), "align_node")
    if not os.path.exists(script):
        pytest.skip("the align_node console script is not installed beside this interpreter")
    env = {**os.environ, "ROS_DOMAIN_ID": str(224 + round(10 * after_s)), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "PYTHONUNBUFFERED": "1"}
    node, output = start([script], env)
    try:
        time.sleep(after_s)
        node.send_signal(signal.SIGINT)
        node.wait(timeout=60)
    finally:
        kill_group(node)
    log = output.text(timeout=10.0)
    assert node.returncode == 0, log
    assert "Traceback" not in log and "KeyboardInterrupt" not in log, log
