"""Typed configuration of unsupervised training, with the paper's recipe as the defaults.

Paper recipe (Jiang et al., ICCV 2021, Sec. 4): Geman-McClure loss (mu = 0.01) between the source aligned
by the final CEM mean mu_T and the target, plus the same loss on the sampling network's prior mean mu0;
Adam, lr 1e-4, weight decay 5e-4, batch 32, 50 epochs; CEM with N = 1000 candidates and T = 10 iterations.
As in the reference code, training runs the CEM without the fused "future" reward and without the
test-time exploration blend. :func:`cpu_preset` gives the settings measured to be practical on a CPU.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from cemnet_ros.core.config import UNSEEDED, CEMConfig
from cemnet_ros.eval.protocol import ProtocolConfig
from cemnet_ros.schema import build, param, section

BEST_METRICS = ("val_mae_r_deg", "val_prior_mae_r_deg", "val_loss")
LR_SCHEDULES = ("constant", "cosine")


def _train_cem() -> CEMConfig:
    """The CEM as the reference trains it: no fused reward, no exploration blend, unseeded noise."""
    return CEMConfig(n_candidates=1000, n_iters=10, n_fused_iters=0, exploration_weight=0.0, seed=UNSEEDED)


@dataclass
class TrainConfig:
    """Everything :class:`cemnet_ros.train.trainer.Trainer` needs."""

    data: str = param("", "an .npz of shapes (points (S, n, 3) [+ labels, split]) or a folder of scans")
    out_dir: str = param("results/train", "output folder (checkpoints, log.csv, curves.png, config.json)")
    # Optimisation.
    epochs: int = param(50, "training epochs (paper: 50)", low=1)
    batch_size: int = param(32, "global batch (paper: 32); split evenly over DDP ranks", low=2)
    lr: float = param(1e-4, "Adam learning rate, > 0 (paper: 1e-4)")
    # "constant" (the paper) or "cosine": lr decays per epoch to lr / 100 at the last epoch, so that short runs
    # end with small steps and settled BatchNorm running statistics.
    lr_schedule: str = param("constant", "learning-rate schedule: 'constant' (the paper) or 'cosine' (decays per "
                             "epoch to lr / 100 at the last epoch)", choices=LR_SCHEDULES)
    weight_decay: float = param(5e-4, "Adam weight decay (paper: 5e-4)", low=0.0)
    loss_mu: float = param(0.01, "Geman-McClure scale mu, > 0 (paper: 0.01)")
    prior_loss_weight: float = param(1.0, "weight of the loss on the prior alignment mu0 (paper: 1)", low=0.0)
    # The CEM inside the training graph, and the CEM used for validation (eval settings: fused reward on).
    cem: CEMConfig = section(_train_cem, "the CEM inside the training graph (no fused reward, no exploration "
                             "blend, unseeded)")
    val_cem: CEMConfig = section(CEMConfig, "the CEM used for validation (eval settings: fused reward on)")
    val_batchnorm: str = param("running", "BatchNorm statistics at validation", choices=("running", "batch"))
    # Validation figure (lower is better) that picks best.npz. On clean pairs the eval-settings CEM saturates
    # (near 0 deg even with an untrained network), so the prior's error is the informative choice there.
    best_metric: str = param("val_mae_r_deg", "validation figure (lower is better) that picks best.npz",
                             choices=BEST_METRICS)
    # Data: pairs follow the evaluation protocol (random pose, partial crop, optional noise).
    protocol: ProtocolConfig = section(ProtocolConfig, "how training/validation pairs are made (the evaluation "
                                       "protocol: random pose, partial crop, optional noise)")
    unseen: bool = param(False, "npz only: train on categories 0-19 (the unseen-category split)")
    val_fraction: float = param(0.1, "share of the training shapes/scans held out for validation, in (0, 1)")
    limit_train: int = param(0, "use at most this many training shapes; 0 = all", low=0)
    limit_val: int = param(0, "use at most this many validation shapes; 0 = all", low=0)
    val_every: int = param(1, "validate every k epochs (and always after the last one)", low=1)
    # Initial weights: "" = random init; an .npz (safe) or an official .pth (needs allow_pickle).
    init_weights: str = param("", "initial weights: '' = random init; an .npz (safe) or an official .pth (needs "
                              "allow_pickle)")
    allow_pickle: bool = param(False, "allow loading official (pickled) .pth weights: only for files you trust")
    resume: bool = param(False, "continue from out_dir/last.npz (+ last_optim.npz)")
    # Wall-clock budget of this invocation: stop (validated, checkpointed) when another epoch would not fit.
    max_minutes: float = param(0.0, "wall-clock budget (minutes) of this invocation: stop (validated, "
                               "checkpointed) when another epoch would not fit; 0 = no budget", low=0.0)
    seed: int = param(123, "seed of the initial weights, the data split and the pairs", low=0)
    threads: int = param(0, "torch (and numba) intra-op threads per process; 0 = torch default", low=0)
    num_workers: int = param(0, "DataLoader worker processes", low=0)
    device: str = param("auto", "torch device: 'auto' (CUDA when available, else CPU), 'cpu', 'cuda', 'cuda:K'")
    progress: bool = param(True, "tqdm progress bars (rank 0 only)")

    def __post_init__(self) -> None:
        if self.epochs < 1:
            raise ValueError("epochs must be >= 1")
        if self.seed < 0:
            raise ValueError("seed must be >= 0")
        if self.batch_size < 2:
            raise ValueError("batch_size must be >= 2 (BatchNorm needs two samples per batch)")
        if self.lr <= 0 or self.weight_decay < 0 or self.loss_mu <= 0 or self.prior_loss_weight < 0:
            raise ValueError("need lr > 0, weight_decay >= 0, loss_mu > 0, prior_loss_weight >= 0")
        if not 0.0 < self.val_fraction < 1.0:
            raise ValueError("val_fraction must lie in (0, 1)")
        if self.val_every < 1:
            raise ValueError("val_every must be >= 1")
        if self.lr_schedule not in LR_SCHEDULES:
            raise ValueError(f"lr_schedule must be one of {LR_SCHEDULES}, not {self.lr_schedule!r}")
        if self.val_batchnorm not in ("running", "batch"):
            raise ValueError(f"val_batchnorm must be 'running' or 'batch', not {self.val_batchnorm!r}")
        if self.best_metric not in BEST_METRICS:
            raise ValueError(f"best_metric must be one of {BEST_METRICS}, not {self.best_metric!r}")
        if self.limit_train < 0 or self.limit_val < 0:
            raise ValueError("limit_train and limit_val must be >= 0 (0 = all)")
        if self.max_minutes < 0:
            raise ValueError("max_minutes must be >= 0 (0 = no budget)")
        if self.threads < 0:
            raise ValueError("threads must be >= 0 (0 = torch default)")
        if self.num_workers < 0:
            raise ValueError("num_workers must be >= 0")


# A CPU hour holds few paper-size batches (32 pairs, N = 1000; timings in docs/training.md): the CPU preset takes
# 4x smaller batches (4x more optimiser steps) at the reference code's learning rate 1e-3 (the paper's 1e-4 is
# too slow for a few hundred steps) and a cheaper validation CEM (N = 300; the fused reward stays on).
CPU_PRESET = {"batch_size": 8, "lr": 1e-3, "lr_schedule": "cosine", "cem.n_candidates": 300, "cem.n_iters": 10,
              "val_cem.n_candidates": 300}


def cpu_preset(config: TrainConfig) -> TrainConfig:
    """``config`` with the CPU-practical batch size, learning rate and CEM sizes of :data:`CPU_PRESET`."""
    return build(config, CPU_PRESET)


def epoch_learning_rate(config: TrainConfig, epoch: int) -> float:
    """Learning rate of epoch ``epoch`` (1-based): constant, or cosine from lr down to lr / 100 at the last epoch."""
    if config.lr_schedule == "constant" or config.epochs == 1:
        return config.lr
    progress = (epoch - 1) / (config.epochs - 1)
    low = config.lr / 100.0
    return low + 0.5 * (config.lr - low) * (1.0 + math.cos(math.pi * progress))
