"""align_node as a process: Ctrl-C ends it cleanly, also when more SIGINTs arrive during its teardown (a terminal
and ``ros2 launch`` both send one)."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest


def _start_node(domain_id: int) -> subprocess.Popen:
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain_id), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "PYTHONUNBUFFERED": "1"}
    return subprocess.Popen([sys.executable, "-m", "cemnet_ros.ros.align_node"], env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)


def _wait_for_line(process: subprocess.Popen, needle: str, timeout: float) -> list[str]:
    """Lines read until one contains ``needle`` (fails the test at ``timeout`` or when the output ends)."""
    lines, deadline = [], time.monotonic() + timeout
    assert process.stdout is not None
    while time.monotonic() < deadline:
        line = process.stdout.readline()
        if not line:
            break
        lines.append(line)
        if needle in line:
            return lines
    process.kill()
    pytest.fail(f"no {needle!r} in the node's output:\n" + "".join(lines))


@pytest.mark.dds
@pytest.mark.parametrize("interrupts", [1, 3])
def test_repeated_sigint_ends_the_node_with_status_0_and_no_traceback(interrupts):
    node = _start_node(domain_id=220 + interrupts)
    try:
        lines = _wait_for_line(node, "engine ready", timeout=120)
        for _ in range(interrupts):
            node.send_signal(signal.SIGINT)
            time.sleep(0.02)
        rest, _ = node.communicate(timeout=60)
    finally:
        node.kill()
    output = "".join(lines) + rest
    assert node.returncode == 0, output
    assert "Traceback" not in output and "KeyboardInterrupt" not in output, output
