"""Atomic file writes: write a temporary file in the same folder, then ``os.replace`` it.

A reader (or a crash mid-write) never sees a half-written result file. :func:`write_report` is the one writer of
the tools' and benchmarks' result files (JSON, markdown); :func:`atomic_file` serves writers that stream
(``np.savez`` of the weights).
"""
from __future__ import annotations

import json
import math
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any, Iterator, Union

import numpy as np

PathLike = Union[str, "os.PathLike[str]"]


@contextmanager
def atomic_file(path: PathLike) -> Iterator[IO[bytes]]:
    """A binary handle on a temporary file beside ``path`` (whose folder must exist); when the block ends without
    an exception the file is synced and replaces ``path``, otherwise it is removed."""
    path = Path(path)
    if not path.parent.is_dir():
        raise FileNotFoundError(f"cannot write {path}: folder {path.parent} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        os.chmod(tmp, 0o644)  # mkstemp makes 0600 files; results are meant to be shared
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def atomic_write_bytes(path: PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (the parent folder must exist). Returns the path."""
    with atomic_file(path) as handle:
        handle.write(data)
    return Path(path)


def atomic_write_text(path: PathLike, text: str) -> Path:
    """UTF-8 text twin of :func:`atomic_write_bytes`."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def write_report(path: PathLike, text: str) -> Path:
    """A result file: its folder created when missing, the text written atomically. Returns the path."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    return atomic_write_text(path, text)


def jsonable(obj: Any) -> Any:
    """Plain JSON types for a report: arrays and numpy scalars to lists and numbers, non-finite floats to null."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return jsonable(obj.item())
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def json_text(obj: Any, indent: int = 1) -> str:
    """``obj`` as strict JSON text (see :func:`jsonable`), newline-terminated."""
    return json.dumps(jsonable(obj), indent=indent, allow_nan=False) + "\n"
