"""cemnet-convert-weights: turn an official (pickled) CEMNet .pth checkpoint into the safe .npz format."""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

from cemnet_ros.core.checkpoint import CheckpointError, load_network, load_weights, save_weights
from cemnet_ros.io.report import Report, emit
from cemnet_ros.tools.cli_errors import reported_errors

PROG = "cemnet-convert-weights"


@dataclass(frozen=True)
class ConvertConfig:
    checkpoint: str  # the official .pth (a pickle: only convert files you trust)
    output: str  # the .npz to write


@dataclass
class ConvertReport(Report):
    path: Path
    n_tensors: int

    def to_markdown(self) -> str:
        return f"wrote {self.path} ({self.n_tensors} tensors)"


def run(config: ConvertConfig) -> ConvertReport:
    """Convert, then load the result into the network: a file that does not load is an error, not a success."""
    state, meta = load_weights(config.checkpoint, allow_pickle=True)
    path = save_weights(config.output, state, {**meta, "converted_from": config.checkpoint})
    load_network(path)
    return ConvertReport(path, len(state))


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__)
    parser.add_argument("checkpoint", help="official .pth (a pickle: only convert files you trust)")
    parser.add_argument("output", help="destination .npz")
    args = parser.parse_args(argv)
    with reported_errors(PROG, CheckpointError) as outcome:
        emit(run(ConvertConfig(args.checkpoint, args.output)))
    return outcome.code


if __name__ == "__main__":
    sys.exit(main())
