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
