"""Typed configuration of the scan pipeline: one schema (:mod:`cemnet_ros.schema`) for the node, the params
file, the replay and the benchmarks.

One ``seed`` for the pipeline's random draws, then sections by concern, named as the parameters are
(``preprocess.max_range``): ``checks`` (plausibility of the input), ``preprocess``, ``registration`` (the
tracking CEM's engine, :mod:`cemnet_ros.core.config`; where it is centred is ``tracking.centre``), ``tracking``
(where it searches), ``adaptive`` (how widely), ``map``, ``polish``, ``health`` (the failure signals' limits) and
``recovery`` (the global search). Both CEMs are named presets (:mod:`.cem_presets`); the engine's configs they
stand for come from :meth:`AlignerConfig.tracking_engine` and :meth:`AlignerConfig.global_search`.
"""
from __future__ import annotations

from dataclasses import dataclass

from cemnet_ros.core.config import EngineConfig, GlobalSearchConfig, NetworkConfig, SearchScatterConfig
from cemnet_ros.pipeline.cem_presets import CEM_PRESET_NAMES, cem_preset
from cemnet_ros.schema import fields_of, param, section, validate

SAMPLING_METHODS = ("random", "farthest")
TRACKING_CENTRES = ("motion", "network", "identity")
RECOVERY_SCATTERS = ("uniform", "network")


@dataclass
class TrackingEngineConfig(NetworkConfig):
    """The tracking CEM's engine: its network settings and its CEM by preset (the seed is the pipeline's)."""

    n_points: int = param(512, "points per cloud fed to the network and the tracking CEM (the polish against the "
                          "map gives the precision)", low=32)
    cem_preset: str = param("tracking", "the tracking CEM (docs/node.md: CEM presets)", choices=CEM_PRESET_NAMES)

    def engine(self, seed: int) -> EngineConfig:
        """The engine's config: these settings, the preset's CEM, ``seed`` for its sub-sampling and its CEM."""
        return EngineConfig(**fields_of(self, NetworkConfig), cem=cem_preset(self.cem_preset, seed), seed=seed)


@dataclass
class RecoverySearchConfig(SearchScatterConfig):
    """The global search's scatter and hypotheses, and the CEM refining each one by preset."""

    refine_preset: str = param("refine", "the CEM that refines each hypothesis (docs/node.md: CEM presets)",
                               choices=CEM_PRESET_NAMES)

    def global_search(self, seed: int) -> GlobalSearchConfig:
        """The core search's config: this scatter, the preset's CEM sampling with ``seed``."""
        return GlobalSearchConfig(**fields_of(self, SearchScatterConfig), refine=cem_preset(self.refine_preset, seed))


@dataclass
class InputChecksConfig:
    """Limits of the plausibility checks (docs/node.md: Input checks)."""

    max_points: int = param(400_000, "more finite points than this are decimated to it, with a warning; 0 = no cap",
                            low=0)
    min_count_ratio: float = param(0.35, "a scan with fewer finite points than this fraction of the recent median "
                                   "is rejected; 0 = off (with the check below)", low=0.0, high=1.0)
    min_coverage_ratio: float = param(0.5, "... or covering fewer azimuth sectors (of 36) than this fraction of "
                                      "the recent median", low=0.0, high=1.0)
    level_window: int = param(20, "scans in the running point-count median", low=1, high=1000)
    relevel_after: int = param(10, "after this many consecutive low-count scans the median restarts from them",
                               low=1)
    future_tolerance: float = param(10.0, "a stamp more than this (s) ahead of the node's clock is rejected; "
                                    "0 = off", low=0.0)
    stamp_jump: float = param(30.0, "a stamp more than this (s, and 20 periods) after the last one, or before it, "
                              "is rejected unless the next scan confirms it; 0 = off", low=0.0)

    def __post_init__(self) -> None:
        validate(self)


@dataclass
class AdaptiveConfig:
    """Spreads in radians and metres; ``factor`` times the RMS prediction error, clipped to [min, max]."""

    initial_rotation: float = param(0.05, "rotation spread (rad) until prediction errors have been observed",
                                    low=1e-4, high=3.2)
    initial_translation: float = param(0.5, "translation spread (m) until prediction errors have been observed",
                                       low=1e-4)
    min_rotation: float = param(0.01, "smallest rotation spread (rad)", low=1e-5, high=3.2)
    min_translation: float = param(0.1, "smallest translation spread (m)", low=1e-5)
    max_rotation: float = param(0.5, "largest rotation spread (rad)", low=1e-5, high=3.2)
    max_translation: float = param(5.0, "largest translation spread (m)", low=1e-5)
    factor: float = param(3.0, "spread = factor x the RMS of the recent prediction errors", low=1e-3)
    window: int = param(100, "prediction errors remembered", low=1)

    def __post_init__(self) -> None:
        validate(self)
        if self.min_rotation > self.max_rotation or self.min_translation > self.max_translation:
            raise ValueError("adaptive spreads need min <= max")


@dataclass
class HealthConfig:
    """Limits of the failure signals (fractions, metres, radians)."""

    min_fitness: float = param(0.15, "inlier fraction after the polish below which a step fails whatever the "
                               "running level: too little overlap to be evidence (a right answer against a young "
                               "map of sparse scans fits ~0.2)", low=0.0, high=0.99)
    fitness_drop: float = param(0.7, "a step fails when its fitness falls below this fraction of the running "
                                "level", low=0.01, high=1.0)
    confirm_ratio: float = param(0.9, "an answer stands without the global search when it fits and covers at "
                                 "least this fraction of the running levels where the prediction expects it; away "
                                 "from the prediction it must, after the search too", low=0.0, high=1.0)
    coverage_distance: float = param(6.0, "a scan point is covered by the map when a map point lies this close "
                                     "(frame voxels)", low=0.1)
    max_seen_through: float = param(0.2, "an answer that puts more of the scan where the map's last scan saw empty "
                                    "space (its sensor looked through it) than this x its fitness does not compete",
                                    low=0.0)
    tie_ratio: float = param(0.95, "distinct answers whose consistency falls short of the best one's by less than "
                             "1 - this of its fitness are a near-tie: the one next to the prediction is kept, "
                             "flagged; with none next to it the step fails as ambiguous", low=0.01, high=1.0)
    level_memory: float = param(0.9, "running fitness and coverage levels: level <- memory * level + (1 - memory) "
                                "* the vouched step's", low=0.0, high=0.999)
    min_conditioning: float = param(0.005, "smallest / largest eigenvalue of the polish's normalised Hessian "
                                    "below which a step is degenerate (flagged; its covariance carries the "
                                    "prediction's uncertainty along the weak direction)", low=0.0, high=0.99)
    neighbour_conditioning: float = param(0.02, "an accepted step whose conditioning is below this (a weakly "
                                          "constrained view: a narrow field of view down a corridor) is polished "
                                          "again from its rotational neighbours: a neighbour that fits about as "
                                          "well flags it, one that fits clearly better replaces it; 0 = never",
                                          low=0.0, high=1.0)
    min_vouched_share: float = param(0.1, "the step that ends a run of degenerate steps is vouched only where at "
                                     "least this share of its fitness lies on the map as last vouched (before the "
                                     "run); otherwise it is flagged and the map restarts from it", low=0.0, high=1.0)
    covariance_inflation: float = param(100.0, "variance factor of a failed step's covariance", low=1.0)

    def __post_init__(self) -> None:
        validate(self)


@dataclass
class PreprocessConfig:
    """What of a scan is used (metres from the sensor)."""

    scale: float = param(0.0, "metres per network unit; 0 = auto (robust radius of the first scan)", low=0.0)
    voxel_size: float = param(0.0, "voxel grid (m); 0 = auto (scale / 100), negative = no voxel grid", low=-1.0,
                              user=True)
    min_range: float = param(0.0, "drop points closer than this to the sensor (m); 0 = off", low=0.0,
                             user=True)
    max_range: float = param(100.0, "drop points farther than this from the sensor (m); 0 = off", low=0.0,
                             user=True)
    min_points: int = param(50, "a scan with fewer points after preprocessing is rejected", low=3)
    sampling: str = param("random", "how the voxel cloud is cut to registration.n_points", choices=SAMPLING_METHODS)
    cem_radius: float = param(1.5, "the CEM's clouds keep the points this close to the sensor (units of scale)",
                              low=1e-3)
    deskew: bool = param(True, "with per-point times (the first field of t, time, offset_time, timestamp; its "
                         "unit detected): undo the motion within each sweep (constant velocity; registered at the "
                         "sweep's middle, published at the stamp); false = no deskew", user=True)

    def __post_init__(self) -> None:
        validate(self)
        if 0 < self.max_range < self.min_range:
            raise ValueError("max_range must be >= min_range (or 0 = no crop)")


@dataclass
class TrackingConfig:
    """Where the tracking CEM searches."""

    centre: str = param("motion", "where the tracking CEM is centred: the constant-velocity prediction, the "
                        "sampling network's mu0, or N(0, identity_sigma) around the last pose",
                        choices=TRACKING_CENTRES)
    identity_sigma: float = param(1.0, "spread of the 'identity' centre (rad and network units; paper: N(0, I))",
                                  low=1e-4)
    local_first: bool = param(True, "polish the prediction first (finely, then from afar); the CEM samples only "
                              "when no answer stands (false: the CEM first on every step, as the method alone)")

    def __post_init__(self) -> None:
        validate(self)


@dataclass
class MapConfig:
    """The local map (a voxel hash map in the odom frame)."""

    voxel_factor: float = param(3.0, "map voxel = this x the frame voxel", low=0.1)
    points_per_voxel: int = param(10, "points kept per map voxel", low=1)

    def __post_init__(self) -> None:
        validate(self)


@dataclass
class PolishConfig:
    """The point-to-plane polish against the map, and the fitness it is judged by."""

    iters: int = param(20, "point-to-plane polish iterations (at most: it stops once a step moves the scan less "
                       "than a hundredth of a frame voxel)", low=1)
    points: int = param(3000, "source points the polish uses at most (a seeded subset of the voxel cloud)", low=10)
    coarse_stride: int = param(3, "the polish's first steps use every this-many-th point, the last ones and the "
                               "Hessian all (1 = all throughout)", low=1)
    wide_distance: float = param(6.0, "pairing distance of the wide polish's basin stage, GICP against the map's "
                                 "last scan (frame voxels)", low=0.1)
    wide_iters: int = param(60, "its iterations at most (a start can be degrees off)", low=1)
    inlier_distance: float = param(2.0, "a point with a map point this close (frame voxels) ...", low=1e-3)
    inlier_residual: float = param(0.05, "... and within this of its plane (m; the sensor's noise, not the "
                                   "scene's size) counts for the fitness", low=1e-4)

    def __post_init__(self) -> None:
        validate(self)


@dataclass
class RecoveryConfig:
    """When and how widely the global search runs (metres and radians; degrees where named ``_deg``)."""

    search: RecoverySearchConfig = section(RecoverySearchConfig, "the global CEM search")
    radius: float = param(10.0, "translation radius (m) searched around the prediction; yaw is searched "
                                   "over the full circle", low=0.0)
    points: int = param(512, "source and map points the global search scores (the polish brings the "
                                 "precision)", low=32)
    turn_yaw_deg: float = param(90.0, "the search also polishes the last pose turned about its z axis by up to "
                                "this (deg) either way; 0 = no turns", low=0.0, high=180.0)
    turn_step_deg: float = param(30.0, "... in steps of this (deg: about the wide polish's reach)", low=1.0,
                                 high=180.0)
    turn_tilt_deg: float = param(20.0, "... each also tilted by this (deg) about its x and y axes either way; 0 = "
                                 "yaw only", low=0.0, high=90.0)
    restart_after: int = param(3, "consecutive failed steps after which the map restarts from the scan (lost)",
                               low=1)
    scatter: str = param("uniform", "the global search's scatter: uniform only, or also recovery.search.n_network "
                         "candidates drawn from the sampling network's raw N(mu0, sigma0)", choices=RECOVERY_SCATTERS)
    weights: str = param("scan", "that network's weights (recovery.scatter 'network'): 'scan' = the package's LiDAR "
                         "scan weights, '' = the package's ModelNet40 weights, 'official' = the official clean "
                         "checkpoint shipped converted, or a .npz / official .pth path")
    allow_pickle: bool = param(False, "allow loading pickled (.pth) recovery weights: only for files you trust")

    def __post_init__(self) -> None:
        validate(self)


@dataclass
class AlignerConfig:
    """Everything the scan pipeline needs: its seed, then sections by concern."""

    seed: int = param(0, "seed of the pipeline's random draws (the scan's and the map's subsets, the global "
                      "search, both CEMs); -1 = the tracking CEM samples unseeded, the rest keeps seed 0", low=-1)
    threads: int = param(0, "threads of every pool a scan runs on (numba's kernels, torch, small_gicp's covariances): "
                         "a robot's spare cores; 0 = all the machine's", low=0, user=True)
    checks: InputChecksConfig = section(InputChecksConfig, "plausibility checks a scan passes first")
    preprocess: PreprocessConfig = section(PreprocessConfig, "what of a scan is used")
    registration: TrackingEngineConfig = section(TrackingEngineConfig, "the tracking CEM and its network")
    tracking: TrackingConfig = section(TrackingConfig, "where the tracking CEM searches")
    adaptive: AdaptiveConfig = section(AdaptiveConfig, "how widely it searches (from the recent prediction errors)")
    map: MapConfig = section(MapConfig, "the local map")
    polish: PolishConfig = section(PolishConfig, "the point-to-plane polish against the map")
    health: HealthConfig = section(HealthConfig, "the failure signals' limits")
    recovery: RecoveryConfig = section(RecoveryConfig, "when and how widely the global search runs")

    def __post_init__(self) -> None:
        validate(self)

    @property
    def draw_seed(self) -> int:
        """The seed of the pipeline's own draws (the scan's and the map's subsets, the search's scatter): ``seed``,
        0 when unseeded."""
        return max(self.seed, 0)

    def tracking_engine(self) -> EngineConfig:
        """The tracking CEM's engine config (its preset, the pipeline's seed)."""
        return self.registration.engine(self.seed)

    def global_search(self) -> GlobalSearchConfig:
        """The global search's config (its refinement's preset, the pipeline's seed)."""
        return self.recovery.search.global_search(self.seed)
