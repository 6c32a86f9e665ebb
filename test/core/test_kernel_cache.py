"""The kernels' on-disk cache: its folder changes with any kernel source, falls back when unwritable, and loads."""
import os
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from cemnet_ros.core import jit, kernel_cache

USES_POLICY = re.compile(r"^from (\.|cemnet_ros\.core\.)jit import", re.MULTILINE)


def test_sources_list_every_kernel_module():
    """A module that defines kernels but is missing from SOURCES could leave its callers' cache stale."""
    package = kernel_cache.PACKAGE
    users = {str(path.relative_to(package)) for path in package.rglob("*.py") if USES_POLICY.search(path.read_text())}
    assert users | {"core/jit.py"} == set(kernel_cache.SOURCES)


def test_digest_changes_with_any_source(tmp_path):
    copy = tmp_path / "cemnet_ros"
    for name in kernel_cache.SOURCES:
        (copy / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(kernel_cache.PACKAGE / name, copy / name)
    digests = {kernel_cache.kernel_digest(copy)}
    for name in kernel_cache.SOURCES:
        with open(copy / name, "a") as handle:
            handle.write("\n# changed\n")
        digests.add(kernel_cache.kernel_digest(copy))
    assert len(digests) == len(kernel_cache.SOURCES) + 1
    assert kernel_cache.kernel_digest(copy) != kernel_cache.kernel_digest()


@pytest.fixture
def roots(monkeypatch):
    """Replace the candidate roots; the chosen folder is looked up again and forgotten afterwards."""
    chosen: list[Path] = []
    monkeypatch.setattr(kernel_cache, "candidate_roots", lambda: chosen)
    kernel_cache.cache_folder.cache_clear()
    yield chosen
    kernel_cache.cache_folder.cache_clear()


def test_unwritable_root_falls_back_to_the_next(tmp_path, roots):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    roots.extend([blocker / "cache", tmp_path / "second"])  # a folder under a file cannot be made, even by root
    folder = Path(kernel_cache.cache_folder())
    assert folder.parent == tmp_path / "second" and folder.name == f"numba-{kernel_cache.kernel_digest()}"


def test_no_writable_root_compiles_uncached_with_a_warning(tmp_path, roots):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    roots.append(blocker / "cache")
    with pytest.warns(RuntimeWarning, match="NUMBA_CACHE_DIR"):
        doubled = jit.kernel(lambda x: 2 * x)
    assert doubled(3) == 6
    assert doubled._cache.cache_path is None  # numba's NullCache: nothing is written


KERNEL_MODULE = """
from cemnet_ros.core.jit import kernel

@kernel(parallel=True, fastmath=True)
def total(x):
    s = 0.0
    for i in numba.prange(x.shape[0]):
        s += x[i]
    return s
"""
RUN = """
import sys
import numpy as np
sys.path.insert(0, sys.argv[1])
import tiny_kernel
print(tiny_kernel.total(np.arange(10.0)), sum(tiny_kernel.total.stats.cache_hits.values()))
"""


@pytest.mark.slow
def test_second_process_loads_the_kernel_from_the_cache(tmp_path):
    """A parallel kernel compiled in one process is loaded, not compiled, in the next (here under NUMBA_CACHE_DIR)."""
    (tmp_path / "tiny_kernel.py").write_text("import numba\n" + textwrap.dedent(KERNEL_MODULE))
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": str(kernel_cache.PACKAGE.parent)}
    runs = [subprocess.run([sys.executable, "-c", RUN, str(tmp_path)], env=env, capture_output=True, text=True,
                           check=True).stdout.split() for _ in range(2)]
    assert runs == [["45.0", "0"], ["45.0", "1"]]
    assert list((tmp_path / "cache").glob("numba-*"))
