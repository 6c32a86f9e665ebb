"""Fixtures of the training tests."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from tiny_training import TINY, box_union_shapes


@pytest.fixture(scope="module")
def shapes_npz(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("shapes") / "tiny.npz"
    n = 12
    np.savez(path, points=box_union_shapes(n, TINY.n_points, seed=1), labels=np.arange(n) % 4,
             split=np.array(["train"] * 10 + ["test"] * 2))
    return path
