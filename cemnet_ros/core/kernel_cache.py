"""Where numba caches the package's kernels on disk: one folder per version of the kernels' source.

numba checks a cached kernel against its own source file only. A kernel that calls a kernel of another module
(the rewards call the lattice's look-up, the map's queries its hash table) carries the callee's machine code, so
it would stay stale when only the callee's file changed. The folder's name carries a digest of every file that
shapes a kernel (:data:`SOURCES`), so any change to them starts an empty cache; numba's own check still guards
each file.

The folder, ``numba-<digest>``, is the first writable one under: ``$NUMBA_CACHE_DIR`` when set, the package's
``__pycache__`` (a checkout, a pip or colcon install the user owns), the user's cache folder
(``$XDG_CACHE_HOME`` or ``~/.cache``, ``cemnet_ros``: a read-only install). When none is writable the kernels are
compiled in each process and a warning says so. Old folders are left in place (a process still running the old
code may write to its own); deleting them is safe.
"""
from __future__ import annotations

import functools
import hashlib
import os
import tempfile
import warnings
from pathlib import Path
from typing import Optional

import numba

PACKAGE = Path(__file__).resolve().parents[1]
# the kernel modules and the policy that compiles them (package-relative); test_kernel_cache checks it is complete
SOURCES = ("core/jit.py", "core/lattice.py", "core/lattice_rewards.py", "pipeline/steps/preprocess.py",
           "pipeline/steps/refine.py", "pipeline/map/voxel_hash.py", "pipeline/map/voxel_normals.py",
           "pipeline/map/voxel_query.py")


def kernel_digest(package: Path = PACKAGE) -> str:
    """A digest of the :data:`SOURCES` under ``package`` (their names and contents)."""
    digest = hashlib.sha256()
    for name in SOURCES:
        digest.update(name.encode() + b"\0" + (package / name).read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def candidate_roots() -> list[Path]:
    """The folders that may hold the cache folder, in order of preference (see the module docstring)."""
    user_cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    chosen = numba.config.CACHE_DIR  # type: ignore[attr-defined]  # $NUMBA_CACHE_DIR, read at numba's import
    return ([Path(chosen)] if chosen else []) + [PACKAGE / "__pycache__", user_cache / "cemnet_ros"]


def writable(folder: Path) -> bool:
    """Whether ``folder`` exists (created if need be) and takes a new file."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError:
        return False
    return True


@functools.lru_cache(maxsize=None)
def cache_folder() -> Optional[str]:
    """The kernels' cache folder for this process; None (and a warning) when no candidate is writable."""
    name = f"numba-{kernel_digest()}"
    for root in candidate_roots():
        if writable(root / name):
            return str(root / name)
    warnings.warn(f"no writable folder for numba's kernel cache among {[str(r) for r in candidate_roots()]}: "
                  "the kernels are compiled in this process (~1 min); set NUMBA_CACHE_DIR to a writable folder",
                  RuntimeWarning, stacklevel=2)
    return None
