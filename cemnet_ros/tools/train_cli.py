"""``cemnet-train``: unsupervised training of the CEMNet sampling network.

Single process:  cemnet-train --data modelnet40.npz --out results/train_modelnet
From a bag:      cemnet-train --bag run.mcap [--topic /points] --out results/train_bag
Several (DDP):   torchrun --nproc_per_node=2 -m cemnet_ros.tools.train_cli --data ... --out ...
``--preset auto`` (default) takes the paper's recipe on CUDA and the measured CPU-practical sizes on a CPU
(see docs/training.md); every explicit flag overrides the preset.
"""
from __future__ import annotations

import argparse
import sys
from typing import Optional, Sequence

from cemnet_ros.core.checkpoint import CheckpointError
from cemnet_ros.replay.bag_types import BagError
from cemnet_ros.schema import add_arguments, build, parameters, parsed_overrides
from cemnet_ros.tools.cli_errors import reported_errors
from cemnet_ros.train import distributed as ddp
from cemnet_ros.train.config import CPU_PRESET, TrainConfig, cpu_preset

# Every TrainConfig field is a flag (--bag, --topic, --epochs, --cem.n_candidates, --protocol.noise, ...) except
# those the CLI-only flags set (--data, --out, --no-progress) and preprocess.deskew (training scans are not deskewed).
TRAIN = parameters(TrainConfig(), exclude=("data", "out_dir", "progress", "preprocess.deskew"))


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="cemnet-train", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--data", default="", help="an .npz of shapes (points, labels, split) or a folder of scans "
                                              "(.ply/.pcd/.npy/.npz/KITTI .bin); or give --bag")
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
    config = build(config, parsed_overrides(args, TRAIN))
    if not (config.data or config.bag):
        raise ValueError("give --data (an .npz of shapes or a folder of scans) or --bag")
    return config


def describe(config: TrainConfig, info: ddp.DistInfo) -> str:
    """The run's one-line header."""
    return (f"cemnet-train: world size {info.world_size}, device {info.device}, batch {config.batch_size}, "
            f"N={config.cem.n_candidates}, T={config.cem.n_iters}, val N={config.val_cem.n_candidates}, "
            f"epochs {config.epochs}, lr {config.lr}")


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = build_parser().parse_args(argv)
    with reported_errors("cemnet-train", RuntimeError) as setup:  # a bad flag value, no CUDA, no torchrun env
        info = ddp.init_distributed(requested_device(args))
        config = config_from_args(args, info.device.type)
    if setup.code:
        return setup.code
    from cemnet_ros.train.run import run  # heavy imports after argument checks

    try:
        with reported_errors("cemnet-train", CheckpointError, BagError) as outcome:  # e.g. an unreadable scan
            if info.is_main:
                print(describe(config, info), flush=True)
            report = run(config, info)
            if info.is_main:
                print(report.to_markdown(), flush=True)
    finally:
        ddp.shutdown(info)
    return outcome.code


if __name__ == "__main__":
    sys.exit(main())
