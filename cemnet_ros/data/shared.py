"""Where the optional real data lives: ``shared/`` next to the repository (KITTI and 7-Scenes samples, ...)."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

REPO = Path(__file__).resolve().parents[2]


def shared_dir() -> Optional[Path]:
    """The repository root's sibling ``shared/`` folder, or None when it is absent."""
    path = REPO.parent / "shared"
    return path if path.is_dir() else None
