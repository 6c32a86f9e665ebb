"""One node as a process: spin until Ctrl-C or a fatal error, tear down once, exit 0 or 2 with one line."""
from __future__ import annotations

import signal
import sys
from typing import Any, Callable, Optional

import rclpy
from rclpy.exceptions import ParameterException
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor

from cemnet_ros.ros.parameters import ConfigError


def run(make_node: Callable[[], Any], name: str, args: Optional[list] = None,
        executor: Callable[[], Executor] = SingleThreadedExecutor) -> None:
    """Spin ``make_node()`` on ``executor()`` until SIGINT or its ``fatal_error``; a fatal configuration or engine
    error is one line on stderr (``<name>: error: ...``) and exit status 2. A SIGINT at any point ends it with
    status 0."""
    rclpy.init(args=args)
    node, error = None, None
    try:
        node = make_node()
        spinner = executor()
        spinner.add_node(node)
        while rclpy.ok() and node.fatal_error is None:
            spinner.spin_once(timeout_sec=0.25)
        error = node.fatal_error
    except (ConfigError, ParameterException) as exc:
        error = str(exc).splitlines()[0]
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if rclpy.ok():
            raise
        # A SIGINT or SIGTERM while the node was being made or spun: rclpy's handler shut the context down, so
        # what ran then failed ("the given context is not valid"). It ends as a Ctrl-C does.
    finally:
        _ignore_interrupts()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    if error:
        print(f"{name}: error: {error}", file=sys.stderr)
        sys.exit(2)


def _ignore_interrupts() -> None:
    """The first Ctrl-C ends the node; more of them (a terminal and ``ros2 launch`` both send one) must not cut
    its teardown short with a KeyboardInterrupt traceback and a killed-by-signal exit status."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # first: a Ctrl-C during what follows is dropped, not raised
    rclpy.signals.uninstall_signal_handlers()  # rclpy's handler hands each SIGINT on to Python's (KeyboardInterrupt)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # uninstalling put back the handler rclpy had found
