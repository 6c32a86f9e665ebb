"""Where the optional real data lives (../shared); tests that need it skip cleanly when it is absent."""
from pathlib import Path

import pytest

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
OFFICIAL_DIR = SHARED / "reference" / "cemnet_official"
MODELNET = SHARED / "data" / "modelnet40_subset.npz"

needs_shared = pytest.mark.skipif(not SHARED.exists(), reason="../shared (real data) is absent")
