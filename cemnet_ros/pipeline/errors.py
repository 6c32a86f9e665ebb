"""Errors of the scan pipeline that its callers (node, replay, training data) handle."""
from __future__ import annotations


class ScanRejected(ValueError):
    """A scan that cannot be aligned; the aligner state is unchanged. ``kind`` names the check (for counting)."""

    def __init__(self, message: str, kind: str = "preprocessing") -> None:
        super().__init__(message)
        self.kind = kind
