"""The package's one numba policy: every kernel (``core``, ``pipeline.preprocess``, ``refine``, ``voxel_*``) uses
:func:`kernel`.

- **nogil**: every kernel releases the GIL, so that the ROS executor thread keeps receiving messages while a
  worker thread runs kernels.
- **fastmath / parallel**: chosen per kernel, at its definition. ``fastmath=True`` is LLVM's full set;
  :data:`FASTMATH_INF_SAFE` drops the no-inf/no-nan assumptions. A kernel that sets no fastmath is compiled
  with that of the first kernel that calls it (numba's flag inheritance, one version per signature: the normals'
  eigen solver gets ``_voxel_normals``' fast-math), so :func:`kernel` passes on only the options it is given.
- **dynamic chunks**: every ``prange`` loop hands out its iterations in chunks (``numba.parallel_chunksize``,
  sized per loop) instead of numba's default of one static block per thread. On a shared machine (the ROS
  executor, the DDS threads, the driver) a pre-empted thread would otherwise hold up the whole kernel while
  the others idle: this is what let a node fed 10x its rate fall well below its own capacity.
- **threading layer**: OpenMP first, which is thread-safe when several threads launch parallel kernels at once
  (a node's worker and a caller), and skips the too-old TBB that some machines carry (numba warns about it on
  every start otherwise). Set here, before any parallel kernel first runs. Threads: numba's default (all cores)
  unless the trainer's ``threads`` sets fewer; a node process makes idle OpenMP threads sleep (``cemnet_ros.ros``).
- **no on-disk cache** (:data:`CACHE`, never ``cache=True`` on a kernel): kernels are compiled once per process
  (each module's ``compile_kernels``; ~10 s for the lattice rewards), never loaded from numba's cache, whose
  byte-identical machine code ran 15-30% slower here than freshly compiled code (docs/evaluation.md).
"""
from __future__ import annotations

from typing import Any, Callable, Optional, Union

import numba

numba.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]  # type: ignore[attr-defined]
CACHE = False  # see the module docstring
# fastmath without the no-inf/no-nan assumptions: distances start at the search bound, never at inf
FASTMATH_INF_SAFE = {"nsz", "arcp", "contract", "afn", "reassoc"}


def kernel(function: Optional[Callable] = None, *, fastmath: Union[bool, set, None] = None,
           parallel: Optional[bool] = None, inline: Optional[str] = None) -> Any:
    """``numba.njit`` under the package's policy: ``@kernel``, or ``@kernel(fastmath=..., parallel=..., inline=...)``.

    The options left at None are not passed to numba (see the module docstring on fastmath inheritance).
    """
    chosen: dict[str, Any] = {"fastmath": fastmath, "parallel": parallel, "inline": inline}
    options = {name: value for name, value in chosen.items() if value is not None}
    compile_ = numba.njit(nogil=True, cache=CACHE, **options)
    return compile_ if function is None else compile_(function)
