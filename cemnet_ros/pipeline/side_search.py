"""A second worker for the global search: one registration at a time on a thread of its own, beside the worker
that aligns the scans (:mod:`.unvouched` says what it checks and why).

Its numba kernels run on :data:`THREADS` thread (numba keeps its bound per calling thread), so that the worker
keeps the others, and its thread runs at a lower priority (:data:`NICENESS`, Linux), so that on a machine with
no core to spare the check takes the time the worker leaves idle; the kernels release the GIL, so the two run
side by side.
"""
from __future__ import annotations

import os
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Callable, Generic, Optional, TypeVar

import numba

from cemnet_ros.pipeline.steps.registration import Registered

THREADS = 1
NICENESS = 19  # the check runs on the time the worker leaves: the newest scan comes first
Key = TypeVar("Key")


class SideSearch(Generic[Key]):
    """Runs one registration beside the worker (the thread is made at the first)."""

    def __init__(self) -> None:
        self._executor: Optional[ThreadPoolExecutor] = None
        self._running: Optional[tuple[Key, Future]] = None

    @property
    def busy(self) -> bool:
        """A registration runs, or ended and waits to be taken in."""
        return self._running is not None

    def start(self, key: Key, register: Callable[[], Registered]) -> None:
        """Run ``register`` beside the worker; :meth:`finished` hands back its result with ``key``."""
        if self._executor is None:
            self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="cemnet-side-search",
                                                initializer=_bound_this_thread)
        self._running = (key, self._executor.submit(register))

    def finished(self) -> Optional[tuple[Key, Registered]]:
        """The registration that ended since the last call (None: none ended); an error raised in it is raised
        here."""
        if self._running is None or not self._running[1].done():
            return None
        key, future = self._running
        self._running = None
        return key, future.result()

    def forget(self) -> None:
        """Drop the running registration's result (it runs to its end unseen)."""
        self._running = None


def _bound_this_thread() -> None:
    """The side thread's bounds, set once when it starts: :data:`THREADS` numba threads, :data:`NICENESS` where
    the system allows it."""
    numba.set_num_threads(min(THREADS, numba.config.NUMBA_NUM_THREADS))  # type: ignore[attr-defined]
    if hasattr(os, "setpriority"):
        try:
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), NICENESS)  # Linux: this thread alone
        except OSError:
            pass
