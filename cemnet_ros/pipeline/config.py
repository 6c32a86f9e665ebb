"""Typed configuration of the scan pipeline: one schema for the node, the YAML, the replay and the benchmarks.

Sections by concern: ``registration`` (the tracking CEM, :mod:`cemnet_ros.core.config`), ``adaptive`` (the search
spread), ``health`` (the failure signals' limits), ``recovery`` (when and how widely the global search runs), and
the preprocessing and map fields of :class:`AlignerConfig` itself.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from cemnet_ros.core import CEMConfig, RegistrationConfig
from cemnet_ros.core.global_search import GlobalSearchConfig
from cemnet_ros.pipeline.adaptive import AdaptiveConfig
from cemnet_ros.pipeline.health import HealthConfig
from cemnet_ros.pipeline.preprocess import SAMPLING_METHODS

PRIORS = ("motion", "network", "identity")


def odometry_registration() -> RegistrationConfig:
    """CEM settings for tracking around a motion prediction: a short search (the recovery is the wide one).

    512 points and a lattice of epsilon / 2 suffice there: the polish against the map gives the precision.
    """
    return RegistrationConfig(n_points=512, cem=CEMConfig(n_candidates=100, n_iters=2, n_fused_iters=0,
                                                          lattice_spacing=0.5))


@dataclass
class RecoveryConfig:
    """When and how widely the global search runs (metres, radians, seconds)."""

    search: GlobalSearchConfig = field(default_factory=GlobalSearchConfig)
    recovery_radius: float = 10.0  # m: translation disc searched around the prediction
    recovery_points: int = 1024  # source and map points the global search scores
    recovery_gap: float = 1.0  # s: a stamp gap longer than this triggers a recovery (a recovery itself takes ~0.5 s)
    ambiguity_ratio: float = 0.9  # a distinct hypothesis this close in fitness makes the answer ambiguous
    polish_distance: float = 6.0  # in frame voxels: the first pairing distance of a hypothesis' polish
    polish_iters: int = 30  # its iterations at that distance (a hypothesis can be degrees off)
    restart_after: int = 3  # consecutive failed steps after which the map restarts from the scan (lost)

    def __post_init__(self) -> None:
        if self.recovery_radius < 0 or self.recovery_gap <= 0 or self.polish_distance <= 0:
            raise ValueError("recovery_radius must be >= 0, recovery_gap and polish_distance > 0")
        if self.recovery_points < 32 or self.restart_after < 1 or self.polish_iters < 1:
            raise ValueError("recovery_points must be >= 32, restart_after and polish_iters >= 1")
        if not 0.0 < self.ambiguity_ratio <= 1.0:
            raise ValueError("ambiguity_ratio must lie in (0, 1]")


@dataclass
class AlignerConfig:
    """Everything the scan pipeline needs; nested sections by concern."""

    registration: RegistrationConfig = field(default_factory=odometry_registration)
    adaptive: AdaptiveConfig = field(default_factory=AdaptiveConfig)
    health: HealthConfig = field(default_factory=HealthConfig)
    recovery: RecoveryConfig = field(default_factory=RecoveryConfig)
    prior: str = "motion"  # tracking CEM centre: "motion" (constant velocity), "network" or "identity"
    identity_sigma: float = 1.0  # rad and network units: spread of the "identity" prior (paper: N(0, I))
    scale: float = 0.0  # metres per network unit; <= 0 = auto (robust radius of the first scan)
    voxel_size: float = 0.0  # metres; 0 = auto (scale / 100); < 0 = no voxel grid
    min_range: float = 0.0  # metres from the sensor; 0 = no lower crop
    max_range: float = 100.0  # metres from the sensor; 0 = no upper crop
    sampling: str = "random"  # how the voxel cloud is cut to n_points: "random" (seeded) or "farthest"
    min_points: int = 50  # fewer points after preprocessing -> ScanRejected
    map_voxel_factor: float = 3.0  # map voxel = this x the frame voxel
    map_points_per_voxel: int = 10
    refine_iters: int = 10  # point-to-plane polish iterations (at most)
    refine_points: int = 3000  # source points the polish uses at most (a seeded subset of the voxel cloud)
    inlier_distance: float = 2.0  # in frame voxels: a point with a map point this close counts for the fitness
    cem_radius: float = 1.5  # in units of scale: the CEM's clouds keep points this close to the sensor

    def __post_init__(self) -> None:
        if self.prior not in PRIORS:
            raise ValueError(f"prior must be one of {PRIORS}, not {self.prior!r}")
        if self.sampling not in SAMPLING_METHODS:
            raise ValueError(f"sampling must be one of {SAMPLING_METHODS}, not {self.sampling!r}")
        if self.identity_sigma <= 0:
            raise ValueError("identity_sigma must be > 0")
        if self.min_points < 3:
            raise ValueError("min_points must be >= 3")
        if 0 < self.max_range < self.min_range:
            raise ValueError("max_range must be >= min_range (or 0 = no crop)")
        if self.map_voxel_factor <= 0 or self.map_points_per_voxel < 1 or self.inlier_distance <= 0:
            raise ValueError("map_voxel_factor, map_points_per_voxel and inlier_distance must be > 0")
        if self.refine_iters < 1:
            raise ValueError("refine_iters must be >= 1")
        if self.refine_points < 10:
            raise ValueError("refine_points must be >= 10")
        if self.cem_radius <= 0:
            raise ValueError("cem_radius must be > 0")
