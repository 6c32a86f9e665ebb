"""cemnet-convert-weights: turn an official (pickled) CEMNet .pth checkpoint into the safe .npz format."""
from __future__ import annotations

import argparse
import sys

from cemnet_ros.core.checkpoint import CheckpointError, load_network, load_weights, save_weights


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("checkpoint", help="official .pth (a pickle: only convert files you trust)")
    parser.add_argument("output", help="destination .npz")
    args = parser.parse_args(argv)
    try:
        state, meta = load_weights(args.checkpoint, allow_pickle=True)
        path = save_weights(args.output, state, {**meta, "converted_from": args.checkpoint})
        load_network(path)  # proves the result loads into the network
    except CheckpointError as exc:
        print(f"cemnet-convert-weights: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {path} ({len(state)} tensors)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
