"""Typed configuration of the CEMNet engine, with the paper's defaults (fields documented for the schema)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

from cemnet_ros.schema import fields_of, param, section, validate

Six = Tuple[float, float, float, float, float, float]
UNSEEDED = -1  # a seed field's value for fresh randomness on every run


def seed_or_none(seed: int) -> Optional[int]:
    """A seed field as numpy / torch take it: None for :data:`UNSEEDED`."""
    return None if seed < 0 else seed


@dataclass
class CEMConfig:
    """The differentiable cross-entropy method (Sec. 3.2 of the paper).

    Actions are 6-vectors ``[euler_z, euler_y, euler_x, tx, ty, tz]`` (radians, cloud units) with
    ``R = Rx(x) @ Ry(y) @ Rz(z)``; a candidate maps source points onto the target: ``y = R x + t``.
    """

    n_candidates: int = param(1000, "N: candidates sampled per iteration", low=2)
    n_iters: int = param(10, "T: iterations", low=1)
    n_fused_iters: int = param(3, "M: first iterations fusing the after-ICP ('future') reward", low=0)
    icp_steps: int = param(3, "point-to-point ICP steps behind the future reward", low=0)
    epsilon: float = param(0.1, "truncation distance of the max-consensus reward (network units)", low=1e-6)
    alpha: float = param(0.5, "weight of the current reward in the fused score", low=0.0, high=1.0)
    # The reference's test-time blend of the sampling network's output: mu0 <- (1-w) mu0,
    # sigma0 <- (1-w) sigma0 + w * exploration_sigma. It widens a confident but wrong network prior; a prior
    # given by the caller (motion model, identity) is used as it is.
    exploration_weight: float = param(0.5, "test-time blend of the network's Gaussian towards exploration_sigma "
                                      "(reference: 0.5; training: 0)", low=0.0, high=1.0)
    exploration_sigma: Six = param((1.0, 1.0, 1.0, 0.5, 0.5, 0.5), "spread the network's Gaussian is blended "
                                   "towards (rad, network units)", low=0.0)
    icp_max_distance: float = param(0.0, "ICP correspondences farther than this are ignored (network units); "
                                    "0 = 2 epsilon", low=0.0)
    refine_icp_steps: int = param(0, "point-to-point ICP refinement steps of mu_T (0 = the paper's method)", low=0)
    lattice_spacing: float = param(0.25, "CPU look-up lattice spacing in units of epsilon: finer = more often the "
                                   "exact nearest neighbour, coarser = a smaller lattice", low=0.01, high=1.0)
    seed: int = param(0, "seed of the CEM's sampling; -1 = unseeded", low=-1)

    def __post_init__(self) -> None:
        validate(self)
        if self.n_fused_iters > self.n_iters:
            raise ValueError(f"n_fused_iters ({self.n_fused_iters}) must not exceed n_iters ({self.n_iters})")

    @property
    def icp_radius(self) -> float:
        return 2.0 * self.epsilon if self.icp_max_distance == 0 else float(self.icp_max_distance)


@dataclass
class NetworkConfig:
    """The sampling network, the clouds it takes and the device: the engine's settings besides its CEM and seed
    (which the scan pipeline chooses by preset and from its one seed)."""

    n_points: int = param(768, "points per cloud fed to the network and the CEM", low=32)
    weights: str = param("", "sampling network weights: '' = the package's (ModelNet40), 'official' = the "
                         "official clean checkpoint shipped converted, 'scan' = the package's LiDAR scan weights, or "
                         "a .npz / official .pth path")
    allow_pickle: bool = param(False, "allow loading pickled (.pth) weights: only for files you trust")
    batchnorm: str = param("running", "BatchNorm statistics of the network ('batch' as the reference, which "
                           "never calls eval())", choices=("batch", "running"))
    device: str = param("auto", "torch device: 'auto' (CUDA when available), 'cpu', 'cuda', 'cuda:1', ...",
                        user=True)

    def __post_init__(self) -> None:
        validate(self)


@dataclass
class EngineConfig(NetworkConfig):
    """The CEM, its clouds and its network: everything :func:`cemnet_ros.core.register` needs besides the two
    clouds and where the CEM's initial distribution comes from (a caller that decides that, as the scan
    pipeline does, configures this alone)."""

    cem: CEMConfig = section(CEMConfig, "the cross-entropy method")
    seed: int = param(0, "seed of the point sub-sampling; -1 = unseeded", low=-1)


@dataclass
class RegistrationConfig(EngineConfig):
    """Everything :func:`cemnet_ros.core.register` needs besides the two clouds: the engine and its prior."""

    prior: str = param("network", "where mu0/sigma0 come from: the sampling network, or N(0, prior_sigma) "
                       "(the paper's no-network ablation)", choices=("network", "identity"))
    prior_sigma: Six = param((1.0,) * 6, "spread of the identity prior (rad, network units)", low=0.0)

    @classmethod
    def of(cls, engine: EngineConfig, prior: str) -> RegistrationConfig:
        """``engine``'s settings with the initial distribution from ``prior`` ('network' or 'identity')."""
        return cls(**fields_of(engine, EngineConfig), prior=prior)


@dataclass
class SearchScatterConfig:
    """How wide the global search looks and how many hypotheses it keeps (units: radians and engine units): all
    of it but the CEM refining them. It has no time budget: what a scan yields never depends on the machine's
    speed."""

    n_scatter: int = param(2000, "candidates of the coarse scatter over yaw and translation", low=1)
    n_network: int = param(500, "with the network's prior (recovery.scatter 'network'): candidates drawn from it, "
                           "N(mu0, (network_scale sigma0)^2), in addition to the uniform scatter", low=0)
    network_scale: float = param(1.0, "k: how much wider than the network's sigma0 those are drawn", low=1e-3)
    coarse_epsilon: float = param(0.2, "epsilon of the coarse scoring (network units; the CEM refinement uses "
                                  "its own)", low=1e-4)
    tilt_sigma: float = param(0.03, "roll and pitch spread of the scatter (rad)", low=0.0)
    height_sigma: float = param(0.01, "z spread of the scatter (network units)", low=0.0)
    n_hypotheses: int = param(4, "distinct hypotheses refined by the CEM", low=1)
    n_seeds: int = param(16, "distinct scatter candidates resampled around", low=1)
    n_per_seed: int = param(50, "candidates drawn around each", low=0)
    resample_sigma: Six = param((0.1, 0.02, 0.02, 0.03, 0.03, 0.005), "spread of the resampling (rad, network "
                                "units)", low=1e-6)
    min_separation_yaw: float = param(0.3, "hypotheses closer in yaw (rad) AND translation count as one", low=0.0)
    min_separation_translation: float = param(0.1, "... and in translation (network units)", low=0.0)
    refine_sigma: Six = param((0.15, 0.02, 0.02, 0.05, 0.05, 0.01), "initial CEM spread per hypothesis (rad, "
                              "network units)", low=1e-6)

    def __post_init__(self) -> None:
        validate(self)
        if self.n_scatter < max(self.n_hypotheses, self.n_seeds):
            raise ValueError("n_scatter must be >= n_hypotheses and n_seeds")


@dataclass
class GlobalSearchConfig(SearchScatterConfig):
    """Everything :func:`cemnet_ros.core.global_search.global_search` needs: the scatter and the CEM refining
    each hypothesis."""

    refine: CEMConfig = section(lambda: CEMConfig(n_candidates=100, n_iters=5, n_fused_iters=2),
                                "the CEM that refines each hypothesis")
