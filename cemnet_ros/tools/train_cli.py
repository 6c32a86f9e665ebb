"""``cemnet-train``: unsupervised training of the CEMNet sampling network.

Single process:  cemnet-train --data modelnet40.npz --out results/train_modelnet
Several (DDP):   torchrun --nproc_per_node=2 -m cemnet_ros.tools.train_cli --data ... --out ...
``--preset auto`` (default) takes the paper's recipe on CUDA and the measured CPU-practical sizes on a CPU
(see docs/training.md); every explicit flag overrides the preset.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from typing import Optional, Sequence

from cemnet_ros.core.checkpoint import CheckpointError
from cemnet_ros.eval.protocol import ProtocolConfig
from cemnet_ros.train import distributed as ddp
from cemnet_ros.train.config import BEST_METRICS, CPU_PRESET, LR_SCHEDULES, TrainConfig, cpu_preset


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="cemnet-train", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--data", required=True, help="an .npz of shapes (points, labels, split) or a folder of scans "
                                                 "(.ply/.pcd/.npy/.npz/KITTI .bin)")
    p.add_argument("--out", required=True, help="output folder (checkpoints, log.csv, curves.png)")
    p.add_argument("--preset", choices=("auto", "paper", "cpu"), default="auto",
                   help=f"paper: batch 32, N=1000; cpu: {CPU_PRESET}; auto: cpu unless CUDA is used")
    p.add_argument("--epochs", type=int, help="paper: 50")
    p.add_argument("--batch-size", type=int, help="global batch (split over DDP ranks)")
    p.add_argument("--lr", type=float, help="Adam learning rate (paper: 1e-4)")
    p.add_argument("--lr-schedule", choices=LR_SCHEDULES, help="constant (paper) or cosine (to lr/100)")
    p.add_argument("--weight-decay", type=float, help="Adam weight decay (paper: 5e-4)")
    p.add_argument("--n-candidates", type=int, help="CEM candidates N while training")
    p.add_argument("--n-iters", type=int, help="CEM iterations T while training")
    p.add_argument("--val-n-candidates", type=int, help="CEM candidates N at validation")
    p.add_argument("--n-points", type=int, default=1024, help="points taken from each shape/scan")
    p.add_argument("--n-partial", type=int, default=768, help="points kept per cloud by the partial crop")
    p.add_argument("--noise", action="store_true", help="clipped Gaussian noise on both clouds")
    p.add_argument("--unseen", action="store_true", help="train on categories 0-19 only (npz data)")
    crop = p.add_mutually_exclusive_group()
    crop.add_argument("--partial", dest="partial", action="store_true", default=True, help="partial crops")
    crop.add_argument("--full", dest="partial", action="store_false", help="full clouds (no crop)")
    p.add_argument("--seed", type=int, default=123)
    p.add_argument("--threads", type=int, help="torch/numba threads per process")
    p.add_argument("--workers", type=int, default=0, help="DataLoader worker processes")
    p.add_argument("--device", default="auto", help="auto | cpu | cuda | cuda:K")
    p.add_argument("--resume", action="store_true", help="continue from OUT/last.npz")
    p.add_argument("--max-minutes", type=float, help="wall-clock budget: stop after the last epoch that fits")
    p.add_argument("--init", help="initial weights: .npz, or an official .pth with --allow-pickle")
    p.add_argument("--allow-pickle", action="store_true", help="allow loading official (pickled) .pth weights")
    p.add_argument("--limit-train", type=int, help="use at most this many training shapes")
    p.add_argument("--limit-val", type=int, help="use at most this many validation shapes")
    p.add_argument("--val-every", type=int, default=1, help="validate every k epochs")
    p.add_argument("--best-metric", choices=BEST_METRICS, default="val_mae_r_deg",
                   help="validation figure that selects best.npz (lower is better)")
    p.add_argument("--no-progress", action="store_true", help="no tqdm bars")
    return p


def config_from_args(args: argparse.Namespace, device_type: str) -> TrainConfig:
    """The preset, then every explicitly given flag on top of it."""
    base = TrainConfig(data=args.data, out_dir=args.out, seed=args.seed, threads=args.threads,
                       num_workers=args.workers, device=args.device, resume=args.resume,
                       max_minutes=args.max_minutes, init_weights=args.init, allow_pickle=args.allow_pickle,
                       unseen=args.unseen, limit_train=args.limit_train, limit_val=args.limit_val,
                       val_every=args.val_every, best_metric=args.best_metric, progress=not args.no_progress,
                       protocol=ProtocolConfig(n_points=args.n_points, n_partial=args.n_partial,
                                               partial=args.partial, noise=args.noise))
    preset = args.preset if args.preset != "auto" else ("paper" if device_type == "cuda" else "cpu")
    config = cpu_preset(base) if preset == "cpu" else base
    overrides = {name: value for name, value in (("epochs", args.epochs), ("batch_size", args.batch_size),
                                                 ("lr", args.lr), ("lr_schedule", args.lr_schedule),
                                                 ("weight_decay", args.weight_decay))
                 if value is not None}
    cem = {k: v for k, v in (("n_candidates", args.n_candidates), ("n_iters", args.n_iters)) if v is not None}
    val_cem = {"n_candidates": args.val_n_candidates} if args.val_n_candidates is not None else {}
    return replace(config, **overrides, cem=replace(config.cem, **cem), val_cem=replace(config.val_cem, **val_cem))


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        info = ddp.init_distributed(args.device)
        config = config_from_args(args, info.device.type)
    except (ValueError, RuntimeError) as exc:
        print(f"cemnet-train: {exc}", file=sys.stderr)
        return 2
    from cemnet_ros.train.trainer import Trainer  # heavy imports after argument checks

    try:
        if info.is_main:
            print(f"cemnet-train: world size {info.world_size}, device {info.device}, batch {config.batch_size}, "
                  f"N={config.cem.n_candidates}, T={config.cem.n_iters}, val N={config.val_cem.n_candidates}, "
                  f"epochs {config.epochs}, lr {config.lr}", flush=True)
        rows = Trainer(config, info).fit()
    except (FileNotFoundError, ValueError, CheckpointError) as exc:
        print(f"cemnet-train: {exc}", file=sys.stderr)
        return 2
    finally:
        ddp.shutdown(info)
    if info.is_main and rows:
        print(f"cemnet-train: {len(rows)} epoch(s) logged in {args.out}/log.csv", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
