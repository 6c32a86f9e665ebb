"""``align_lifecycle_node``: align_node as a managed (lifecycle) node, for a system that brings it up in order.

The same parameters (declared at construction, read on ``configure``), topics and services as ``align_node``:

- construction: the engine starts loading in a background thread (:class:`~.engine_load.EngineLoad`: the numba
  kernels, compiled first when their cache is not complete, then torch and the weights);
- ``configure``: read the parameters and wait for the engine (what is left of its seconds); a bad parameter or an
  engine that does not load fails the transition, the node stays unconfigured;
- ``activate``: subscribe and publish (:class:`~cemnet_ros.ros.alignment.Alignment`);
- ``deactivate``: unsubscribe, finish the queue, destroy the publishers and services; the engine, the map and the
  trajectory are kept, so a reactivation continues ``odom`` where it stopped;
- ``cleanup``: drop the engine, the map and the trajectory (a later ``configure`` loads again and waits for it);
- ``shutdown``: all of the above.

rclpy (Jazzy) runs a transition inside the ``change_state`` service's callback and has no asynchronous transitions,
so ``configure`` holds one executor thread while it waits. The lifecycle services have a callback group of their own
and the process spins a multi-threaded executor (:func:`main`): parameter services, timers and the other services
keep answering during the wait, and transitions still run one at a time.
"""
from __future__ import annotations

import time
from typing import Any, Optional

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.lifecycle import LifecycleNode, LifecycleNodeMixin, LifecycleState, TransitionCallbackReturn
from rclpy.node import Node

from cemnet_ros.ros.align_node import log_parameters
from cemnet_ros.ros.alignment import Alignment
from cemnet_ros.ros.engine_load import EngineLoad
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
        # The lifecycle services' own group: a configure that waits for the engine holds only it. rclpy Jazzy's
        # LifecycleNode.__init__ does not pass a callback_group on to LifecycleNodeMixin, so both are called here.
        Node.__init__(self, "align_node", **kwargs)
        LifecycleNodeMixin.__init__(self, callback_group=MutuallyExclusiveCallbackGroup())
        declare(self)
        self._configured: Optional[tuple[NodeConfig, AlignerSession, ExtrinsicHold]] = None
        self._alignment: Optional[Alignment] = None
        self._loading: Optional[EngineLoad] = None
        try:
            self._loading = EngineLoad(self.get_logger(), *read(self))
        except ConfigError:
            pass  # configure reads the parameters again and fails with the reason
        else:
            self.get_logger().info("unconfigured; the engine loads in the background (configure waits for it)")

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            cfg, pipeline_config = read(self)
        except ConfigError as exc:
            self.get_logger().error(f"configure failed: {exc}")
            return FAILURE
        log_parameters(self, cfg, pipeline_config)
        load, self._loading = self._loading or EngineLoad(self.get_logger(), cfg, pipeline_config), None
        start = time.monotonic()
        if not load.wait(cancelled=lambda: not self.context.ok()):
            load.close()
            return FAILURE  # shutting down
        if load.seconds is None:
            self.get_logger().error(f"configure failed: {load.session.fatal_error}")
            return FAILURE
        self._configured = (load.cfg, load.session, load.extrinsic)
        self.get_logger().info(f"configured: engine ready after {load.seconds:.1f} s ({load.kernels}; configure "
                               f"waited {time.monotonic() - start:.1f} s)")
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
        if self._loading is not None:
            self._loading.close()
            self._loading = None
        if self._configured is not None:
            self._configured[1].close()
            self._configured = None

    def destroy_node(self) -> None:
        self._deactivate()
        self._cleanup()
        super().destroy_node()


def main(args: Optional[list] = None) -> None:
    """Spin until SIGINT (two executor threads: see the module docstring); a parameter override of the wrong type is
    one line on stderr and exit status 2."""
    run(AlignLifecycleNode, "align_lifecycle_node", args, executor=lambda: MultiThreadedExecutor(num_threads=2))


if __name__ == "__main__":
    main()
