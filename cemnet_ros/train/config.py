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
from cemnet_ros.pipeline.config import PreprocessConfig, RecoveryConfig, TrackingEngineConfig
from cemnet_ros.schema import build, param, section, validate

from .known_motion import KnownMotionConfig

BEST_METRICS = ("val_mae_r_deg", "val_prior_mae_r_deg", "val_loss")
OBJECTIVES = ("paper", "known_motion")
CENTRES = ("sensor", "centroid")
LR_SCHEDULES = ("constant", "cosine")


def _train_cem() -> CEMConfig:
    """The CEM as the reference trains it: no fused reward, no exploration blend, unseeded noise."""
    return CEMConfig(n_candidates=1000, n_iters=10, n_fused_iters=0, exploration_weight=0.0, seed=UNSEEDED)


@dataclass
class ScanPairConfig:
    """How training pairs are made from the scans of a bag: the situations the node's recovery searches.

    A pair is a scan and the scan ``1..max_gap`` later (share ``consecutive``) or the scan and itself; each cloud
    loses a random azimuth sector, gets its own subset and noise, and the source is moved by a random rigid
    motion drawn as the node's recovery scatters its candidates (yaw over the full circle, translation on a disc
    of ``radius`` metres, roll, pitch and height spread as its default ``recovery.search``).
    """

    n_points: int = param(TrackingEngineConfig().n_points, "points per cloud (the node's registration.n_points)",
                          low=32)
    consecutive: float = param(0.5, "share of pairs made of two scans (the rest pair a scan with itself)",
                               low=0.0, high=1.0)
    max_gap: int = param(1, "a consecutive pair's scans are at most this many scans apart", low=1)
    radius: float = param(RecoveryConfig().radius, "random motion: translation uniform on a disc of this radius "
                          "(m; the node's recovery.radius), yaw uniform over the full circle", low=0.0)
    crop_deg: float = param(90.0, "partial crop: each cloud loses a random azimuth sector of up to this many "
                            "degrees", low=0.0, high=360.0)
    noise: float = param(0.02, "Gaussian noise (m) added to every coordinate of both clouds", low=0.0)
    centre: str = param("sensor", "origin of the network units: 'sensor' (the target's sensor, as the node's "
                        "recovery centres its search: the motion's yaw turns about the sensor) or 'centroid' (the "
                        "target's centroid, as the tracking CEM centres its clouds)", choices=CENTRES)

    def __post_init__(self) -> None:
        validate(self)


@dataclass
class TrainConfig:
    """Everything :class:`cemnet_ros.train.trainer.Trainer` needs."""

    data: str = param("", "an .npz of shapes (points (S, n, 3) [+ labels, split]) or a folder of scans")
    bag: str = param("", "instead of data: a rosbag2 bag (.mcap/.db3 file or folder) of PointCloud2 scans, "
                     "trained on in the node's units; several bags: comma-separated, each in its own units")
    topic: str = param("", "the bags' PointCloud2 topic; '' = each bag's only one")
    out_dir: str = param("results/train", "output folder (checkpoints, log.csv, curves.png, config.json)")
    objective: str = param("paper", "'paper': the CEM in the loop, Geman-McClure losses of mu_T and mu0 "
                           "(unsupervised); 'known_motion': the sampling network alone, taught the random motion of "
                           "pairs made of one cloud (self-supervised, no CEM in the loop: a step is ~10x cheaper)",
                           choices=OBJECTIVES)
    known_motion: KnownMotionConfig = section(KnownMotionConfig, "objective 'known_motion': its terms' weights and "
                                              "scales")
    # Optimisation.
    epochs: int = param(50, "training epochs (paper: 50)", low=1)
    batch_size: int = param(32, "global batch (paper: 32); split evenly over DDP ranks", low=2)
    lr: float = param(1e-4, "Adam learning rate (paper: 1e-4)", low=1e-9)
    # "constant" (the paper) or "cosine": lr decays per epoch to lr / 100 at the last epoch, so that short runs
    # end with small steps and settled BatchNorm running statistics.
    lr_schedule: str = param("constant", "learning-rate schedule: 'constant' (the paper) or 'cosine' (decays per "
                             "epoch to lr / 100 at the last epoch)", choices=LR_SCHEDULES)
    weight_decay: float = param(5e-4, "Adam weight decay (paper: 5e-4)", low=0.0)
    loss_mu: float = param(0.01, "Geman-McClure scale mu (paper: 0.01)", low=1e-6)
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
    preprocess: PreprocessConfig = section(PreprocessConfig, "bag: the node's preprocessing (range crop, voxel "
                                           "grid, CEM radius, scale = metres per network unit)")
    scans: ScanPairConfig = section(ScanPairConfig, "bag: how pairs are made from its scans")
    unseen: bool = param(False, "npz only: train on categories 0-19 (the unseen-category split)")
    val_fraction: float = param(0.1, "share of the training shapes/scans held out for validation", low=0.01,
                                 high=0.99)
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
        validate(self)
        if self.data and self.bag:
            raise ValueError("give data (shapes or a folder of scans) or bag, not both")


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


def bag_paths(config: TrainConfig) -> list[str]:
    """The bags of ``config.bag`` (comma-separated)."""
    return [path.strip() for path in config.bag.split(",") if path.strip()]
