"""The tools' shared ending for bad input: one line ``<prog>: error: <message>`` on stderr and exit status 2,
instead of a traceback, for a missing or malformed file (PointCloudFileError, ...) or a bad value."""
from __future__ import annotations

import sys
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Iterator

from cemnet_ros.io.optional import MissingOptional

# FileNotFoundError, PointCloudFileError, ...; and an optional library the input needs (Pillow for depth PNGs)
INPUT_ERRORS: tuple[type[Exception], ...] = (OSError, ValueError, MissingOptional)


@dataclass
class Outcome:
    """How a :func:`reported_errors` block ended: ``code`` 0, or 2 after a reported error."""

    code: int = 0


@contextmanager
def reported_errors(prog: str, *extra: type[Exception]) -> Iterator[Outcome]:
    """Run the block; an OSError, ValueError or one of ``extra`` ends it with one line on stderr (the message's
    whitespace folded, so it stays one line) and ``outcome.code = 2`` for main to return."""
    outcome = Outcome()
    try:
        yield outcome
    except (*INPUT_ERRORS, *extra) as exc:
        message = " ".join(str(exc).split()) or type(exc).__name__
        print(f"{prog}: error: {message}", file=sys.stderr)
        outcome.code = 2
