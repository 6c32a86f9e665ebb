"""What the point cloud file readers share: the typed error for bad files and the text-header splitting of
PLY and PCD (both are ASCII header lines followed by a text or binary body)."""
from __future__ import annotations

from pathlib import Path
from typing import Callable, List, Tuple

MAX_HEADER_BYTES = 1 << 16


class PointCloudFileError(ValueError):
    """A point cloud file that cannot be read: empty, truncated, malformed or without usable points.

    The message is ``<path>: <problem>``; a ValueError, so callers that catch ValueError keep working.
    """

    def __init__(self, path: Path, problem: str) -> None:
        super().__init__(f"{path}: {problem}")
        self.path = path
        self.problem = problem


def read_header(path: Path, raw: bytes, terminator: Callable[[str], bool]) -> Tuple[List[str], bytes]:
    """Split a text header (lines up to and including the one ``terminator`` accepts) from the body."""
    lines: List[str] = []
    pos = 0
    while True:
        end = raw.find(b"\n", pos)
        if end < 0 or end > MAX_HEADER_BYTES:
            raise PointCloudFileError(path, "header is not terminated (truncated or not a point cloud file)")
        try:
            line = raw[pos:end].decode("ascii").strip()
        except UnicodeDecodeError:
            raise PointCloudFileError(path, "header contains non-text bytes (corrupt file)") from None
        pos = end + 1
        lines.append(line)
        if terminator(line):
            return lines, raw[pos:]


def to_int(value: str, what: str, path: Path) -> int:
    """A header count (>= 0) or a PointCloudFileError naming the header entry."""
    try:
        number = int(value)
    except ValueError:
        raise PointCloudFileError(path, f"{what} must be an integer, got {value!r}") from None
    if number < 0:
        raise PointCloudFileError(path, f"{what} must be >= 0, got {number}")
    return number
