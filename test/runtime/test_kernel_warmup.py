"""The kernel cache's completeness mark: it holds only for the kernel sources (paths, sizes, modification times),
numba and CPU it was written for, as numba's cached code does; without it a node warms up before subscribing."""
import json
import os
import shutil

import pytest

from cemnet_ros.core import kernel_cache
from cemnet_ros.runtime import kernel_warmup
from cemnet_ros.runtime.kernel_warmup import MARK, cache_complete, cache_mark


@pytest.fixture
def package(tmp_path):
    """A copy of the kernel sources, as another install of the package."""
    copy = tmp_path / "cemnet_ros"
    for name in kernel_cache.SOURCES:
        (copy / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(kernel_cache.PACKAGE / name, copy / name)
    return copy


def _mark(folder, package, **changes):
    folder.mkdir(exist_ok=True)
    (folder / MARK).write_text(json.dumps({**cache_mark(package), **changes}))


def test_a_cache_is_complete_only_with_the_mark_of_a_finished_warm_up(tmp_path, package):
    folder = tmp_path / "cache"
    folder.mkdir()
    assert not cache_complete(str(folder), package)
    (folder / MARK).write_text("{not json")
    assert not cache_complete(str(folder), package)
    _mark(folder, package)
    assert cache_complete(str(folder), package)


@pytest.mark.parametrize("name", kernel_cache.SOURCES)
def test_a_touched_kernel_source_voids_the_mark(tmp_path, package, name):
    """numba checks each cached kernel against its source's size and modification time: so does the mark."""
    folder = tmp_path / "cache"
    _mark(folder, package)
    stat = (package / name).stat()
    os.utime(package / name, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000_000))
    assert not cache_complete(str(folder), package)


def test_another_install_numba_or_cpu_voids_the_mark(tmp_path, package):
    folder = tmp_path / "cache"
    _mark(folder, package)
    assert not cache_complete(str(folder), kernel_cache.PACKAGE)  # the same sources elsewhere: numba's own paths
    for changes in ({"numba": "0.0.0"}, {"target": "aarch64-unknown-linux-gnu"}, {"cpu": "another-cpu"},
                    {"cpu_features": "+sse2"}):
        _mark(folder, package, **changes)
        assert not cache_complete(str(folder), package), changes


def test_without_a_writable_cache_folder_the_cache_is_never_complete(tmp_path, package, monkeypatch):
    _mark(tmp_path / "cache", package)
    monkeypatch.setattr(kernel_warmup, "cache_folder", lambda: None)  # kernel_cache found no writable folder
    assert not cache_complete(None, package)
