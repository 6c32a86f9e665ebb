"""Typed configuration of the CEMNet engine, with the paper's defaults."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional, Tuple

Six = Tuple[float, float, float, float, float, float]


@dataclass
class CEMConfig:
    """The differentiable cross-entropy method (Sec. 3.2 of the paper).

    Actions are 6-vectors ``[euler_z, euler_y, euler_x, tx, ty, tz]`` (radians, cloud units) with
    ``R = Rx(x) @ Ry(y) @ Rz(z)``; a candidate maps source points onto the target: ``y = R x + t``.
    """

    n_candidates: int = 1000  # N
    n_iters: int = 10  # T
    n_fused_iters: int = 3  # M: iterations that fuse the "future" (after-ICP) reward
    icp_steps: int = 3  # ICP steps behind the future reward
    epsilon: float = 0.1  # truncation of the max-consensus reward
    alpha: float = 0.5  # weight of the current reward in the fused score
    # The reference's test-time exploration blend of the sampling network's output: mu0 <- (1-w) mu0,
    # sigma0 <- (1-w) sigma0 + w * exploration_sigma (0.5 at test time, 0 in training). It widens a confident but
    # wrong network prior; a prior given by the caller (motion model, identity) is used as it is.
    exploration_weight: float = 0.5
    exploration_sigma: Six = (1.0, 1.0, 1.0, 0.5, 0.5, 0.5)
    # ICP correspondences farther than this (cloud units) are ignored; None = 2 * epsilon.
    icp_max_distance: Optional[float] = None
    # Optional point-to-point ICP refinement of mu_T (0 = off = the paper's method).
    refine_icp_steps: int = 0
    # CPU look-up lattice spacing in units of epsilon: finer = more often the exact nearest neighbour, coarser =
    # a smaller lattice (faster to build, fewer cache misses on large scenes).
    lattice_spacing: float = 0.25
    seed: Optional[int] = 0

    def __post_init__(self) -> None:
        if self.n_candidates < 2:
            raise ValueError("n_candidates must be >= 2")
        if self.n_iters < 1:
            raise ValueError("n_iters must be >= 1")
        if not 0 <= self.n_fused_iters <= self.n_iters:
            raise ValueError("n_fused_iters must lie in [0, n_iters]")
        if self.epsilon <= 0:
            raise ValueError("epsilon must be > 0")
        if not 0.0 <= self.alpha <= 1.0:
            raise ValueError("alpha must lie in [0, 1]")
        if not 0.0 <= self.exploration_weight <= 1.0:
            raise ValueError("exploration_weight must lie in [0, 1]")
        if self.icp_steps < 0 or self.refine_icp_steps < 0:
            raise ValueError("ICP step counts must be >= 0")
        if not 0.0 < self.lattice_spacing <= 1.0:
            raise ValueError("lattice_spacing must lie in (0, 1]")

    @property
    def icp_radius(self) -> float:
        return 2.0 * self.epsilon if self.icp_max_distance is None else float(self.icp_max_distance)


@dataclass
class RegistrationConfig:
    """Everything :func:`cemnet_ros.core.register` needs besides the two clouds."""

    cem: CEMConfig = field(default_factory=CEMConfig)
    n_points: int = 768  # points per cloud fed to the network and the CEM
    # Where mu0/sigma0 come from: "network" (sampling network) or "identity" (mu0 = 0, sigma0 = prior_sigma,
    # the paper's no-network ablation uses N(0, I)).
    prior: str = "network"
    prior_sigma: Six = (1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    # Weights: None = the package's own weights; "official" = the official clean checkpoint shipped converted;
    # a path to a .npz (safe format) or an official .pth.
    weights: Optional[str] = None
    # Official .pth checkpoints are pickles: loading them needs this explicit opt-in.
    allow_pickle: bool = False
    # BatchNorm statistics of the network: "batch" (as the reference, which never calls eval()) or "running".
    batchnorm: str = "running"
    device: str = "auto"  # "auto" = CUDA when available, else CPU
    seed: Optional[int] = 0  # seeds the point sub-sampling

    def __post_init__(self) -> None:
        if self.prior not in ("network", "identity"):
            raise ValueError(f"prior must be 'network' or 'identity', not {self.prior!r}")
        if self.batchnorm not in ("batch", "running"):
            raise ValueError(f"batchnorm must be 'batch' or 'running', not {self.batchnorm!r}")
        if self.n_points < 32:
            raise ValueError("n_points must be >= 32 (the network's k-NN graph needs k=20 neighbours)")
