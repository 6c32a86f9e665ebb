"""The bound on every thread pool a pipeline runs (``AlignerConfig.threads``): numba's kernels, torch's operators
and small_gicp's covariances (:mod:`.map.gicp_cloud` reads numba's bound).

numba keeps its bound per calling thread, so the aligner sets it on every call, from the thread that runs the
scan; torch's is the process's. The kernels' sums run over a fixed number of chunks, so the bound changes the
time a scan takes, not its answer.
"""
from __future__ import annotations

import numba
import torch

TORCH_THREADS = torch.get_num_threads()  # torch's own choice, before any bound


def bound_threads(threads: int) -> None:
    """At most ``threads`` threads for the work this thread starts (0: numba's ``NUMBA_NUM_THREADS`` and torch's
    own choice)."""
    available = numba.config.NUMBA_NUM_THREADS  # type: ignore[attr-defined]
    numba.set_num_threads(min(threads, available) if threads > 0 else available)
    wanted = threads if threads > 0 else TORCH_THREADS
    if torch.get_num_threads() != wanted:
        torch.set_num_threads(wanted)
