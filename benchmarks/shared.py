"""Where the optional real data lives: ``shared/`` next to the repository (KITTI and 7-Scenes samples, the official
checkpoints, ...). The one place that says so: the tests, scripts and tools take :data:`SHARED` from here."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"


def shared_dir() -> Optional[Path]:
    """:data:`SHARED` (the repository root's sibling ``shared/`` folder), or None when it is absent."""
    return SHARED if SHARED.is_dir() else None
