"""The ros2 CLI run as a user runs it, for the tests: its output read by a thread, a private DDS domain,
Ctrl-C (or a kill) to its whole process group, ``ros2 param dump`` without a daemon."""
from __future__ import annotations

import os
import random
import signal
import subprocess
import threading
import time

import pytest
from node_harness import wait_for


def start(command: list, env: dict) -> tuple[subprocess.Popen, "Output"]:
    """``command`` in its own process group (a terminal's job), stdout and stderr together, with Ctrl-C's default
    disposition (a test suite started in the background of a script inherits SIGINT ignored, which a terminal's
    job does not)."""
    process = subprocess.Popen(command, env=env, text=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                               start_new_session=True, preexec_fn=_terminal_signals)
    return process, Output(process)


def _terminal_signals() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def interrupt(process: subprocess.Popen, timeout: float = 60.0) -> None:
    """Ctrl-C in a terminal: SIGINT to the whole group (ros2 launch / ros2 run and their nodes each get one)."""
    os.killpg(process.pid, signal.SIGINT)
    process.wait(timeout=timeout)


def domain_id() -> int:
    """A random DDS domain for one test's processes (a fixed one would meet another run's nodes)."""
    return random.Random(os.getpid() ^ time.time_ns()).randint(120, 200)


class Output:
    """A process's output lines, read by a thread (a pipe read in the test's thread can block or hide lines)."""

    def __init__(self, process: subprocess.Popen) -> None:
        self.lines: list = []
        self._thread = threading.Thread(target=self._read, args=(process,), daemon=True)
        self._thread.start()

    def _read(self, process: subprocess.Popen) -> None:
        assert process.stdout is not None
        for line in process.stdout:
            self.lines.append(line)

    def wait_for(self, needle: str, timeout: float) -> bool:
        """Whether a line with ``needle`` came within ``timeout`` (False at once when the output has ended)."""
        wait_for(lambda: any(needle in line for line in self.lines) or not self._thread.is_alive(), timeout)
        return any(needle in line for line in self.lines)

    def text(self, timeout: float = 0.0) -> str:
        """All lines so far (``timeout``: wait for the end of the output first)."""
        self._thread.join(timeout)
        return "".join(self.lines)


def param_dump(env: dict) -> subprocess.CompletedProcess:
    """``ros2 param dump /align_node`` without a daemon (none is left behind); its discovery gets a few tries."""
    for _ in range(3):
        dump = subprocess.run(["ros2", "param", "dump", "--no-daemon", "--spin-time", "2", "/align_node"], env=env,
                              capture_output=True, text=True, timeout=60)
        if dump.returncode == 0:
            return dump
    pytest.fail(f"ros2 param dump failed: {dump.stderr}")


def kill_group(process: subprocess.Popen) -> None:
    """Kill whatever of the process's group still runs (nothing, when the launch stopped its nodes)."""
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
