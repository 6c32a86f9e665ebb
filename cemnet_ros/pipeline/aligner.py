"""Scan-to-scan (sequential) and source-to-target (pair) alignment with CEMNet, for odometry.

Sequential mode aligns each scan (source) to the previous one (target): the registration maps the current
scan into the previous one, i.e. it is T_prev_curr, and ``pose_k = pose_{k-1} @ T_prev_curr``.

Units: the network and the CEM's epsilon live on the ModelNet unit sphere. Both clouds are centred on the
target's centroid and divided by ``scale`` (metres per network unit) before registration, and the result is
mapped back to metres. ``scale <= 0`` ("auto") fixes it on the first target cloud to its robust radius (90th
percentile of distances to the median point), which makes a 50 m LiDAR scan and a 3 m RGB-D frame both about
unit size. ``voxel_size = 0`` ("auto") is ``scale / 100``, in the spirit of KISS-ICP's ``max_range / 100``.

``refine_iters`` point-to-plane ICP steps on the voxel clouds polish the CEM's answer (see
:mod:`cemnet_ros.pipeline.refine`); 0 keeps the paper's pure CEMNet.

A step is flagged (``accepted`` False, ``reason`` set, covariance inflated) when its fitness is below
``fitness_threshold`` or when the registration disagrees with the motion prediction by more than the jump
limits; the motion model's prediction is then used instead of the registration. A stamp going backwards
(e.g. a looping bag) keeps the pose and restarts from the new scan; a repeated stamp is skipped.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Optional

import numpy as np
from scipy.spatial.transform import Rotation

from cemnet_ros.core import CEMConfig, Registrar, RegistrationConfig
from cemnet_ros.pipeline.covariance import covariance_from_sigma
from cemnet_ros.pipeline.motion import ConstantVelocity
from cemnet_ros.pipeline.preprocess import (SAMPLING_METHODS, crop_range, finite_points, robust_radius,
                                            subsample, voxel_downsample)
from cemnet_ros.pipeline.refine import PlaneTarget, point_to_plane_icp

PRIORS = ("motion", "network", "identity")


def odometry_registration() -> RegistrationConfig:
    """CEM settings for scan-to-scan odometry around a motion prediction.

    The paper's N=1000, T=10, M=3 search the whole space of an object pair from a network guess; around a
    constant-velocity prediction a short search suffices and keeps a 10 Hz LiDAR stream on a 2-core CPU
    (measured in docs/node.md). The paper's settings stay one parameter away.
    """
    return RegistrationConfig(cem=CEMConfig(n_candidates=100, n_iters=3, n_fused_iters=0))


class ScanRejected(ValueError):
    """A scan that cannot be aligned (e.g. too few points after preprocessing); the aligner state is unchanged."""


@dataclass
class AlignerConfig:
    """Everything the scan pipeline needs; ``registration`` holds the CEM/network settings (n_points, ...)."""

    registration: RegistrationConfig = field(default_factory=odometry_registration)
    prior: str = "motion"  # "motion" (constant velocity), "network" (sampling network) or "identity"
    prior_sigma_rotation: float = 0.05  # rad: CEM spread around the motion prediction
    prior_sigma_translation: float = 0.5  # metres: CEM spread around the motion prediction
    identity_sigma: float = 1.0  # rad and network units: spread of the "identity" prior (paper: N(0, I))
    scale: float = 0.0  # metres per network unit; <= 0 = auto (robust radius of the first target cloud)
    voxel_size: float = 0.0  # metres; 0 = auto (scale / 100); < 0 = no voxel grid
    min_range: float = 0.0  # metres from the sensor; 0 = no lower crop
    max_range: float = 100.0  # metres from the sensor; 0 = no upper crop
    sampling: str = "random"  # how the voxel centroids are cut to n_points: "random" (seeded) or "farthest"
    min_points: int = 50  # fewer points after preprocessing -> ScanRejected
    fitness_threshold: float = 0.3  # below: flagged, prediction used, covariance inflated
    covariance_inflation: float = 100.0  # variance factor of a flagged step
    max_jump_translation: float = 1.0  # network units: registration vs prediction disagreement limit
    max_jump_rotation: float = 0.5  # rad: same for rotation
    refine_iters: int = 5  # point-to-plane ICP steps on the voxel clouds after the CEM; 0 = the paper's method
    refine_points: int = 5000  # source points those steps use at most (a seeded subset of the voxel cloud)

    def __post_init__(self) -> None:
        if self.prior not in PRIORS:
            raise ValueError(f"prior must be one of {PRIORS}, not {self.prior!r}")
        if self.sampling not in SAMPLING_METHODS:
            raise ValueError(f"sampling must be one of {SAMPLING_METHODS}, not {self.sampling!r}")
        if self.prior_sigma_rotation <= 0 or self.prior_sigma_translation <= 0 or self.identity_sigma <= 0:
            raise ValueError("prior sigmas must be > 0")
        if self.min_points < 3:
            raise ValueError("min_points must be >= 3")
        if 0 < self.max_range < self.min_range:
            raise ValueError("max_range must be >= min_range (or 0 = no crop)")
        if self.covariance_inflation < 1.0:
            raise ValueError("covariance_inflation must be >= 1")
        if self.refine_iters < 0:
            raise ValueError("refine_iters must be >= 0")
        if self.refine_points < 10:
            raise ValueError("refine_points must be >= 10")


@dataclass
class AlignmentStep:
    """One processed scan: the accumulated pose odom->sensor and the registration's quality."""

    stamp_ns: int
    pose: np.ndarray  # (4, 4)
    relative: Optional[np.ndarray]  # (4, 4) T_prev_curr, None for the first scan / after a restart
    covariance: np.ndarray  # (6, 6) ROS order x, y, z, roll, pitch, yaw
    fitness: float
    accepted: bool
    latency_s: float
    n_points: int
    reason: str = ""


@dataclass
class _Cloud:
    """A preprocessed scan: the voxel cloud (ICP refinement) and its n_points subset (CEMNet), metres."""

    dense: np.ndarray
    sampled: np.ndarray
    _plane: Optional[PlaneTarget] = None

    def refine_source(self, n: int) -> np.ndarray:
        """At most ``n`` points of the dense cloud (seeded subset): the source of the ICP polish."""
        if len(self.dense) <= n:
            return self.dense
        return self.dense[np.random.default_rng(0).choice(len(self.dense), n, replace=False)]

    @property
    def plane(self) -> PlaneTarget:
        """The dense cloud as an ICP target (built on first use, kept while this scan is the reference)."""
        if self._plane is None:
            self._plane = PlaneTarget(self.dense)
        return self._plane


def _angle(transform: np.ndarray) -> float:
    return float(np.linalg.norm(Rotation.from_matrix(transform[:3, :3]).as_rotvec()))


class ScanAligner:
    """Stateful scan pipeline: preprocessing, prior, CEMNet registration, gating, pose accumulation."""

    def __init__(self, config: Optional[AlignerConfig] = None, registrar: Optional[Registrar] = None) -> None:
        self.config = config or AlignerConfig()
        reg_prior = "network" if self.config.prior == "network" else "identity"
        self._registrar = registrar or Registrar(dataclasses.replace(self.config.registration, prior=reg_prior))
        self._fixed_scale = self.config.scale if self.config.scale > 0 else None
        self.reset()

    @property
    def scale(self) -> Optional[float]:
        """Metres per network unit (None until the first target fixed it in auto mode)."""
        return self._scale

    @property
    def voxel(self) -> float:
        """Voxel size (m) of the last preprocessed cloud; 0 = no voxel grid, or nothing preprocessed yet."""
        return self._voxel

    def reset(self) -> None:
        """Forget the reference scan, the pose and the motion model (the auto scale is measured again)."""
        self._scale = self._fixed_scale
        self._voxel = 0.0
        self._motion = ConstantVelocity()
        self._pose = np.eye(4)
        self._reference: Optional[_Cloud] = None
        self._last_stamp: Optional[int] = None
        self._target_raw: Optional[np.ndarray] = None
        self._target_pre: Optional[_Cloud] = None

    # -- public API ---------------------------------------------------------------------------------------
    def process(self, points: np.ndarray, stamp_ns: int) -> AlignmentStep:
        """Sequential mode: align this scan to the previous one and accumulate the pose."""
        start = time.perf_counter()
        stamp_ns = int(stamp_ns)
        cloud = self._prepare(points)
        if self._last_stamp is not None and stamp_ns == self._last_stamp:
            return self._held(stamp_ns, start, len(cloud.sampled), "duplicate stamp: scan skipped")
        if self._reference is None or stamp_ns < self._last_stamp:
            restarted = self._reference is not None
            back_s = (self._last_stamp - stamp_ns) * 1e-9 if restarted else 0.0
            self._motion.reset()
            self._motion.update(self._pose, stamp_ns)
            self._reference, self._last_stamp = cloud, stamp_ns
            reason = f"stamp went back {back_s:.3f} s: restarted from this scan, pose kept" if restarted else ""
            return AlignmentStep(stamp_ns, self._pose.copy(), None, self._floor_cov(), 1.0, not restarted,
                                 time.perf_counter() - start, len(cloud.sampled), reason)
        predicted = self._motion.predict_relative(stamp_ns)
        relative, cov, fitness, accepted, reason = self._register(cloud, self._reference, predicted,
                                                                  have_prediction=True)
        self._pose = self._pose @ relative
        self._motion.update(self._pose, stamp_ns)
        self._reference, self._last_stamp = cloud, stamp_ns
        return AlignmentStep(stamp_ns, self._pose.copy(), relative, cov, fitness, accepted,
                             time.perf_counter() - start, len(cloud.sampled), reason)

    def align_pair(self, source: np.ndarray, target: np.ndarray, stamp_ns: int) -> AlignmentStep:
        """Pair mode: the pose of ``source`` in the frame of ``target`` (a reused target is preprocessed once)."""
        start = time.perf_counter()
        stamp_ns = int(stamp_ns)
        if target is not self._target_raw:
            self._target_pre, self._target_raw = self._prepare(target), target
        cloud = self._prepare(source)
        if self._last_stamp is not None and stamp_ns < self._last_stamp:
            self._motion.reset()
        have_prediction = self._motion.last_pose is not None
        predicted = self._motion.predict(stamp_ns)
        pose, cov, fitness, accepted, reason = self._register(cloud, self._target_pre, predicted,
                                                              have_prediction=have_prediction)
        previous = self._motion.last_pose
        relative = None if previous is None else np.linalg.inv(previous) @ pose
        self._motion.update(pose, stamp_ns)
        self._pose, self._last_stamp = pose, stamp_ns
        return AlignmentStep(stamp_ns, pose.copy(), relative, cov, fitness, accepted,
                             time.perf_counter() - start, len(cloud.sampled), reason)

    # -- internals -----------------------------------------------------------------------------------------
    def _prepare(self, points: np.ndarray) -> _Cloud:
        """Preprocess to metres; the first cloud seen fixes the auto scale. Raises ScanRejected."""
        cfg = self.config
        cropped = crop_range(finite_points(points), cfg.min_range, cfg.max_range)
        if self._scale is None:
            if len(cropped) < cfg.min_points:
                raise ScanRejected(f"too few points: {len(cropped)} after range crop, need {cfg.min_points}")
            radius = robust_radius(cropped)
            if not radius > 0:
                raise ScanRejected("degenerate cloud: all points coincide, cannot measure its scale")
            self._scale = radius
        self._voxel = max(cfg.voxel_size if cfg.voxel_size != 0 else self._scale / 100.0, 0.0)
        dense = voxel_downsample(cropped, self._voxel)
        if len(dense) < cfg.min_points:
            raise ScanRejected(f"too few points: {len(dense)} after preprocessing, need {cfg.min_points}")
        sampled = subsample(dense, cfg.registration.n_points, cfg.sampling, cfg.registration.seed or 0)
        return _Cloud(dense, sampled)

    def _prior_sigma(self) -> np.ndarray:
        cfg = self.config
        if cfg.prior == "identity":
            return np.full(6, cfg.identity_sigma)
        return np.array([cfg.prior_sigma_rotation] * 3 + [cfg.prior_sigma_translation / self._scale] * 3)

    def _register(self, source: _Cloud, target: _Cloud, predicted: np.ndarray, have_prediction: bool):
        """Register in network units; gate on fitness and jumps. Returns (T, covariance, fitness, ok, reason)."""
        cfg, scale = self.config, self._scale
        centre = target.sampled.mean(axis=0)
        to_units = np.eye(4)
        to_units[:3, :3] /= scale
        to_units[:3, 3] = -centre / scale
        from_units = np.linalg.inv(to_units)
        src_u = (source.sampled - centre) / scale
        tgt_u = (target.sampled - centre) / scale
        prior_sigma = self._prior_sigma()
        if cfg.prior == "network":
            res = self._registrar.register(src_u, tgt_u)
        else:
            prior = predicted if cfg.prior == "motion" else np.eye(4)
            res = self._registrar.register(src_u, tgt_u, prior_pose=to_units @ prior @ from_units,
                                           prior_sigma=prior_sigma)
        transform = from_units @ np.asarray(res.transform, dtype=np.float64) @ to_units
        transform[3] = (0.0, 0.0, 0.0, 1.0)
        if cfg.refine_iters > 0:
            start = cfg.registration.cem.epsilon * scale / 2.0
            end = 2.0 * self._voxel if self._voxel > 0 else start / 8.0
            transform = point_to_plane_icp(source.refine_source(cfg.refine_points), target.plane, transform, start,
                                           end, cfg.refine_iters)
        fitness = float(res.fitness)
        reason = ""
        if fitness < cfg.fitness_threshold:
            reason = f"low fitness {fitness:.3f} < {cfg.fitness_threshold:.3f}"
        elif have_prediction:
            error = np.linalg.inv(predicted) @ transform
            jump_m, jump_rad = float(np.linalg.norm(error[:3, 3])), _angle(error)
            if jump_m > cfg.max_jump_translation * scale or jump_rad > cfg.max_jump_rotation:
                reason = (f"jump: registration differs from the motion prediction by {jump_m:.3f} m, "
                          f"{np.degrees(jump_rad):.1f} deg")
        if not reason:
            return transform, covariance_from_sigma(res.sigma, scale), fitness, True, ""
        sigma = np.maximum(np.abs(np.asarray(res.sigma, dtype=np.float64)), prior_sigma)
        cov = covariance_from_sigma(sigma, scale, inflate=cfg.covariance_inflation)
        if have_prediction:
            return predicted, cov, fitness, False, reason + "; motion prediction used"
        return transform, cov, fitness, False, reason

    def _floor_cov(self) -> np.ndarray:
        return covariance_from_sigma(np.zeros(6), self._scale)

    def _held(self, stamp_ns: int, start: float, n_points: int, reason: str) -> AlignmentStep:
        return AlignmentStep(stamp_ns, self._pose.copy(), None, self._floor_cov(), 0.0, False,
                             time.perf_counter() - start, n_points, reason)
