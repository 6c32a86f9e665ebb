"""Command-line flags for the CEMNet engine shared by cemnet-eval, cemnet-bench and cemnet-register."""
from __future__ import annotations

import argparse
from dataclasses import replace

from cemnet_ros.core.config import CEMConfig, RegistrationConfig

# flag -> CEMConfig field; None on the command line keeps the paper's default.
_CEM_FLAGS = {
    "n_candidates": int, "n_iters": int, "n_fused_iters": int, "epsilon": float, "alpha": float,
    "exploration_weight": float,
}


def add_engine_args(parser: argparse.ArgumentParser) -> None:
    """Add --weights, --allow-pickle, --prior, --batchnorm, --seed and the CEM overrides to ``parser``."""
    group = parser.add_argument_group("CEMNet engine")
    group.add_argument("--weights", default=None,
                       help="network weights: a safe .npz, an official .pth (needs --allow-pickle), or 'official' "
                            "(the official clean checkpoint shipped converted); default: the package's own weights")
    group.add_argument("--allow-pickle", action="store_true",
                       help="allow loading pickled official .pth checkpoints (only for files you trust)")
    group.add_argument("--prior", choices=("network", "identity"), default="network",
                       help="initial CEM distribution: the sampling network or N(0, I) (paper's ablation)")
    group.add_argument("--batchnorm", choices=("batch", "running"), default=None,
                       help="BatchNorm statistics at inference (reference: batch); default: the config's")
    group.add_argument("--seed", type=int, default=0, help="seed of the CEM sampling and sub-sampling")
    defaults = CEMConfig()
    for name, kind in _CEM_FLAGS.items():
        group.add_argument("--" + name.replace("_", "-"), type=kind, default=None,
                           help=f"CEM {name} (default {getattr(defaults, name)})")


def config_from_args(args: argparse.Namespace) -> RegistrationConfig:
    """The :class:`RegistrationConfig` the engine flags describe (ValueError on inconsistent values)."""
    overrides = {name: getattr(args, name) for name in _CEM_FLAGS if getattr(args, name) is not None}
    if "n_iters" in overrides and "n_fused_iters" not in overrides:  # e.g. --n-iters 2 alone stays valid
        overrides["n_fused_iters"] = min(CEMConfig().n_fused_iters, overrides["n_iters"])
    cem = replace(CEMConfig(), seed=args.seed, **overrides)
    config = RegistrationConfig(cem=cem, prior=args.prior, weights=args.weights, allow_pickle=args.allow_pickle,
                                seed=args.seed)
    if args.batchnorm is not None:
        config = replace(config, batchnorm=args.batchnorm)
    return config
