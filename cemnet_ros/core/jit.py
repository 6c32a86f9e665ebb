"""The package's one numba policy: every kernel (``core``, ``pipeline.steps.preprocess`` and ``refine``,
``pipeline.map.voxel_*``) uses :func:`kernel`.

- **nogil**: every kernel releases the GIL, so that the ROS executor thread keeps receiving messages while a
  worker thread runs kernels.
- **fastmath / parallel**: chosen per kernel, at its definition. ``fastmath=True`` is LLVM's full set;
  :data:`FASTMATH_INF_SAFE` drops the no-inf/no-nan assumptions. A kernel that sets no fastmath is compiled
  with that of the first kernel that calls it (numba's flag inheritance, one version per signature: the normals'
  eigen solver gets ``_voxel_normals``' fast-math), so :func:`kernel` passes on only the options it is given.
- **static loop splits**: under the OpenMP and workqueue threading layers numba gives each thread one
  contiguous block of a ``prange`` loop's iterations whatever ``numba.parallel_chunksize`` asks (chunks are
  balanced only under TBB), so no kernel sets a chunk size; the context manager would also make the kernel
  uncachable (numba 0.68: ``cache=True`` fails on it with an AttributeError).
- **threading layer**: OpenMP first, which is thread-safe when several threads launch parallel kernels at once
  (a node's worker and a caller), and skips the too-old TBB that some machines carry (numba warns about it on
  every start otherwise). Set here, before any parallel kernel first runs. Threads: numba's default (all cores)
  unless the trainer's ``threads`` sets fewer; a node process makes idle OpenMP threads sleep (``cemnet_ros.ros``).
- **on-disk cache** (:data:`CACHE`): every kernel is cached by numba (``cache=True``) in a folder per version of
  the kernels' source (:mod:`.kernel_cache`, which says where and why), so only a process that finds no cache
  compiles them (~1 min on 2 cores for the aligner's kernels; each module's ``compile_kernels`` does it at start).
  Loaded kernels run as fast as compiled ones (docs/evaluation.md, ``scripts/bench_jit_cache.py``).
"""
from __future__ import annotations

from typing import Any, Callable, Optional, Union

import numba

from .kernel_cache import cache_folder

numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]  # type: ignore[attr-defined]
CACHE = True  # see the module docstring
# fastmath without the no-inf/no-nan assumptions: distances start at the search bound, never at inf
FASTMATH_INF_SAFE = {"nsz", "arcp", "contract", "afn", "reassoc"}


def kernel(function: Optional[Callable] = None, *, fastmath: Union[bool, set, None] = None,
           parallel: Optional[bool] = None, inline: Optional[str] = None) -> Any:
    """``numba.njit`` under the package's policy: ``@kernel``, or ``@kernel(fastmath=..., parallel=..., inline=...)``.

    The options left at None are not passed to numba (see the module docstring on fastmath inheritance).
    """
    chosen: dict[str, Any] = {"fastmath": fastmath, "parallel": parallel, "inline": inline}
    options = {name: value for name, value in chosen.items() if value is not None}

    def compile_(py_function: Callable) -> Any:
        folder = cache_folder() if CACHE else None
        if folder is None:
            return numba.njit(nogil=True, **options)(py_function)
        previous = numba.config.CACHE_DIR  # type: ignore[attr-defined]
        numba.config.CACHE_DIR = folder  # type: ignore[attr-defined]  # numba's locator reads it right here
        try:
            return numba.njit(nogil=True, cache=True, **options)(py_function)
        finally:
            numba.config.CACHE_DIR = previous  # type: ignore[attr-defined]

    return compile_ if function is None else compile_(function)
