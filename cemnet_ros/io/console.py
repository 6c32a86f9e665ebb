"""Progress and log lines of long jobs (benchmarks, tools): on stderr, so stdout keeps the report."""
from __future__ import annotations

import sys
from typing import Iterable, TypeVar

from tqdm import tqdm

T = TypeVar("T")


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def progress(items: Iterable[T], desc: str) -> Iterable[T]:
    """A tqdm bar on stderr that disappears when done."""
    return tqdm(items, desc=desc, file=sys.stderr, leave=False, mininterval=1.0)
