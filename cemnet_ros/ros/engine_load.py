"""The engine of a lifecycle node, loading in a background thread from the node's construction on.

rclpy's lifecycle transitions are synchronous (Jazzy): ``on_configure`` must return its result, so the executor
thread that runs it waits for the engine. Loading starts when the node is made (its parameters are read-only, so
they are the ones ``configure`` reads) and ``configure`` only waits for the remainder (:meth:`EngineLoad.wait`); the
node's other callback groups keep answering meanwhile (:mod:`.align_lifecycle_node`).
"""
from __future__ import annotations

import threading
from typing import Any, Callable, Optional

from cemnet_ros.ros.align_node import new_session
from cemnet_ros.ros.kernels import counted_load, prepare_kernels
from cemnet_ros.ros.node_config import NodeConfig


class EngineLoad:
    """A session for ``cfg`` (and the extrinsic its outputs use) whose kernels and engine load in a thread."""

    def __init__(self, logger: Any, cfg: NodeConfig, pipeline_config: Any) -> None:
        self.cfg = cfg
        self.session, self.extrinsic = new_session(cfg, pipeline_config)
        self._seconds: Optional[float] = None
        self._kernels = ""
        self._thread = threading.Thread(target=self._load, args=(logger,), name="cemnet_load", daemon=True)
        self._thread.start()

    def _load(self, logger: Any) -> None:
        prepare_kernels(logger)
        self._seconds, self._kernels = counted_load(self.session)

    def wait(self, cancelled: Callable[[], bool]) -> bool:
        """Block until the load has ended (True) or ``cancelled()`` says to give up (False; asked every 0.25 s, so
        that a shutdown does not wait for the rest of a load)."""
        while self._thread.is_alive() and not cancelled():
            self._thread.join(0.25)
        return not self._thread.is_alive()

    @property
    def seconds(self) -> Optional[float]:
        """How long the ended load took (None: it failed, ``session.fatal_error`` says why)."""
        return self._seconds

    @property
    def kernels(self) -> str:
        """How the loaded engine's kernels came, e.g. "numba kernels: 15 loaded from the cache, 0 compiled"."""
        return self._kernels

    def close(self) -> None:
        """Drop it: a worker waiting for the engine gives up (the thread itself ends with its load)."""
        self.session.close()
