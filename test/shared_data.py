"""Where the optional real data lives (../shared: :data:`benchmarks.shared.SHARED`); tests that
need it use :func:`requires_shared` and skip cleanly when it is absent."""
from pathlib import Path

import pytest

from benchmarks.shared import SHARED

OFFICIAL_DIR = SHARED / "reference" / "cemnet_official"
MODELNET = SHARED / "data" / "modelnet40_subset.npz"
KITTI = SHARED / "data" / "kitti_sample"


def requires_shared(path: Path = SHARED):
    """The one marker of a test on real data: ``shared_data``, and a skip when ``path`` is absent."""
    skip = pytest.mark.skipif(not path.exists(), reason=f"needs {path.relative_to(SHARED.parent)} (real data)")
    return lambda test: pytest.mark.shared_data(skip(test))
