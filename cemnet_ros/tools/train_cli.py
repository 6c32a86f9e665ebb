"""``cemnet-train``: unsupervised training of the CEMNet sampling network.

Single process:  cemnet-train --data modelnet40.npz --out results/train_modelnet
Several (DDP):   torchrun --nproc_per_node=2 -m cemnet_ros.tools.train_cli --data ... --out ...
``--preset auto`` (default) takes the paper's recipe on CUDA and the measured CPU-practical sizes on a CPU
(see docs/training.md); every explicit flag overrides the preset.
"""
from __future__ import annotations

import argparse
import sys
from typing import Optional, Sequence

from cemnet_ros.core.checkpoint import CheckpointError
from cemnet_ros.schema import add_arguments, build, parameters, parsed_overrides
from cemnet_ros.tools.cli_errors import reported_errors
from cemnet_ros.train import distributed as ddp
from cemnet_ros.train.config import CPU_PRESET, TrainConfig, cpu_preset

# Every TrainConfig field is a flag (--epochs, --cem.n_candidates, --protocol.noise, ...) except those the
# CLI-only flags set: --data, --out and --no-progress.
TRAIN = parameters(TrainConfig(), exclude=("data", "out_dir", "progress"))


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="cemnet-train", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--data", required=True, help="an .npz of shapes (points, labels, split) or a folder of scans "
                                                 "(.ply/.pcd/.npy/.npz/KITTI .bin)")
    p.add_argument("--out", required=True, help="output folder (checkpoints, log.csv, curves.png)")
    preset = ", ".join(f"{k}={v}" for k, v in CPU_PRESET.items())
    p.add_argument("--preset", choices=("auto", "paper", "cpu"), default="auto",
                   help=f"paper: the TrainConfig defaults (batch 32, N=1000); cpu: {preset}; auto: cpu unless "
                        "CUDA is used. Explicit flags override the preset")
    p.add_argument("--no-progress", action="store_true", help="no tqdm bars")
    add_arguments(p, TRAIN, "training (TrainConfig; docs/training.md)")
    return p


def requested_device(args: argparse.Namespace) -> str:
    """The ``--device`` given, else TrainConfig's default."""
    return parsed_overrides(args, TRAIN).get("device", TrainConfig().device)


def config_from_args(args: argparse.Namespace, device_type: str) -> TrainConfig:
    """The preset, then every explicitly given flag on top of it."""
    base = TrainConfig(data=args.data, out_dir=args.out, progress=not args.no_progress)
    preset = args.preset if args.preset != "auto" else ("paper" if device_type == "cuda" else "cpu")
    config = cpu_preset(base) if preset == "cpu" else base
    return build(config, parsed_overrides(args, TRAIN))


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        info = ddp.init_distributed(requested_device(args))
        config = config_from_args(args, info.device.type)
    except (ValueError, RuntimeError) as exc:
        print(f"cemnet-train: {exc}", file=sys.stderr)
        return 2
    from cemnet_ros.train.trainer import Trainer  # heavy imports after argument checks

    try:
        with reported_errors("cemnet-train", CheckpointError) as outcome:  # e.g. an unreadable scan file
            if info.is_main:
                print(f"cemnet-train: world size {info.world_size}, device {info.device}, batch {config.batch_size}, "
                      f"N={config.cem.n_candidates}, T={config.cem.n_iters}, val N={config.val_cem.n_candidates}, "
                      f"epochs {config.epochs}, lr {config.lr}", flush=True)
            rows = Trainer(config, info).fit()
    finally:
        ddp.shutdown(info)
    if outcome.code:
        return outcome.code
    if info.is_main and rows:
        print(f"cemnet-train: {len(rows)} epoch(s) logged in {args.out}/log.csv", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
