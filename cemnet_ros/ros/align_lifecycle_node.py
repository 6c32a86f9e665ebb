"""``align_lifecycle_node``: align_node as a managed (lifecycle) node, for a system that brings it up in order.

The same parameters (declared at construction, read on ``configure``), topics and services as ``align_node``:

- ``configure``: read the parameters and load the engine (seconds; the transition answers when it is loaded); a bad
  parameter or an engine that does not load fails the transition, the node stays unconfigured;
- ``activate``: subscribe and publish (:class:`~cemnet_ros.ros.alignment.Alignment`);
- ``deactivate``: unsubscribe, finish the queue, destroy the publishers and services; the engine, the map and the
  trajectory are kept, so a reactivation continues ``odom`` where it stopped;
- ``cleanup``: drop the engine, the map and the trajectory (a later ``configure`` rereads the parameters);
- ``shutdown``: all of the above.
"""
from __future__ import annotations

from typing import Any, Optional

from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from cemnet_ros.ros.align_node import log_parameters, new_session
from cemnet_ros.ros.alignment import Alignment
from cemnet_ros.ros.node_config import NodeConfig
from cemnet_ros.ros.parameters import ConfigError, declare, read
from cemnet_ros.ros.process import run
from cemnet_ros.runtime.aligner_session import AlignerSession
from cemnet_ros.runtime.extrinsic_hold import ExtrinsicHold

SUCCESS, FAILURE = TransitionCallbackReturn.SUCCESS, TransitionCallbackReturn.FAILURE


class AlignLifecycleNode(LifecycleNode):
    """align_node's outputs while active; raises ConfigError for a parameter override of the wrong type."""

    fatal_error: Optional[str] = None  # a failed transition leaves the process running, for another try

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("align_node", **kwargs)
        declare(self)
        self._configured: Optional[tuple[NodeConfig, AlignerSession, ExtrinsicHold]] = None
        self._alignment: Optional[Alignment] = None

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            cfg, pipeline_config = read(self)
        except ConfigError as exc:
            self.get_logger().error(f"configure failed: {exc}")
            return FAILURE
        log_parameters(self, cfg, pipeline_config)
        session, extrinsic = new_session(cfg, pipeline_config)
        seconds = session.load()
        if seconds is None:
            self.get_logger().error(f"configure failed: {session.fatal_error}")
            return FAILURE
        self._configured = (cfg, session, extrinsic)
        self.get_logger().info(f"configured: engine ready after {seconds:.1f} s")
        return SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        assert self._configured is not None  # the state machine activates a configured node only
        cfg, session, extrinsic = self._configured
        self._alignment = Alignment(self, cfg, session, extrinsic)
        self._alignment.status.ready = True
        self.get_logger().info(f"active: subscribed ({cfg.mode} mode)")
        return SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._deactivate()
        self.get_logger().info("inactive: unsubscribed; the engine, map and trajectory are kept")
        return SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._cleanup()
        self.get_logger().info("unconfigured: the engine, map and trajectory are dropped")
        return SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._deactivate()
        self._cleanup()
        return SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._deactivate()
        self._cleanup()
        return SUCCESS  # back to unconfigured

    def _deactivate(self) -> None:
        if self._alignment is not None:
            self._alignment.destroy()
            self._alignment = None

    def _cleanup(self) -> None:
        if self._configured is not None:
            self._configured[1].close()
            self._configured = None

    def destroy_node(self) -> None:
        self._deactivate()
        self._cleanup()
        super().destroy_node()


def main(args: Optional[list] = None) -> None:
    """Spin until SIGINT; a parameter override of the wrong type is one line on stderr and exit status 2."""
    run(AlignLifecycleNode, "align_lifecycle_node", args)


if __name__ == "__main__":
    main()
