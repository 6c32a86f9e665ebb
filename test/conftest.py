"""Shared test fixtures."""
import numpy as np
import pytest


@pytest.fixture
def bracket():
    """The package's procedural asymmetric shape, 1024 points in the unit sphere."""
    from cemnet_ros.data.shapes import bracket_shape
    return bracket_shape(1024, seed=0).astype(np.float64)
