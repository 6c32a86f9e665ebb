"""Judging a registration without ground truth (step 4 of the recipe in :mod:`..aligner`), and what is published.

An :class:`Estimate` is a registration and its verdict before it is committed: failures (it cannot be vouched
for: the prediction is published instead), notes (degenerate, an ambiguity resolved: flagged, its pose used) and
the covariance from the polish's Hessian. An :class:`AlignmentStep` is what the aligner returns for a scan.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.steps.covariance import (
    Conditioning,
    covariance_from_hessian,
    flat_covariance,
    keep_prediction_along,
)
from cemnet_ros.pipeline.steps.frame import Frame
from cemnet_ros.pipeline.steps.health import HealthMonitor, Signals, disagreement
from cemnet_ros.pipeline.steps.refine import PolishResult

LINEAR_LIMIT = 0.1  # rad: up to this rotation from the prediction a degenerate direction falls back on it
MIN_POLISH_PAIRS = 10  # a polish with fewer point-to-plane pairs constrains nothing


@dataclass
class AlignmentStep:
    """One processed scan: the pose T_odom_sensor and whether the node can vouch for it."""

    stamp_ns: int
    pose: np.ndarray  # (4, 4)
    relative: Optional[np.ndarray]  # (4, 4) T_prev_curr, None for the first scan / after a restart
    covariance: np.ndarray  # (6, 6) ROS order x, y, z, roll, pitch, yaw (docs/node.md: frame and meaning)
    fitness: float
    accepted: bool
    latency_s: float
    n_points: int
    reason: str = ""
    recovered: bool = False  # this step ran the global search
    recovery_reason: str = ""  # why it ran (first pair, stamp gap, tracking failed, requested)
    degenerate: bool = False  # a direction was unconstrained: the prediction was kept along it
    signals: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)  # (kind, message) from the input checks (decimated, restarted)
    origin: str = ""  # the start the published answer was polished from: prediction, cem, last pose, search
    effort: float = 1.0  # the share of the polishes' and the search's budgets this scan had (a live node behind)
    polishes: int = 0  # answers polished and judged for this scan (the cost of its decision)
    answer: Optional[np.ndarray] = None  # (4, 4) the registered answer judged, also when flagged (None: none)
    map_restarted: bool = False  # the map restarted from this scan (the first scan, or lost)

    @classmethod
    def registered(cls, estimate: Estimate, *, stamp_ns: int, pose: np.ndarray, relative: Optional[np.ndarray],
                   covariance_inflation: float, latency_s: float, n_points: int, reason: str,
                   recovery_reason: str, polishes: int = 0, carried: Optional[np.ndarray] = None) -> AlignmentStep:
        """A registered scan: its verdict, signals, covariance and origin from ``estimate``; ``pose`` is the one
        published (the prediction when the step failed); ``carried``: what the previous pose's error adds to the
        step's covariance (:func:`~.covariance.carried_into_step`; none in pair mode)."""
        return cls(stamp_ns=stamp_ns, pose=pose.copy(), relative=relative,
                   covariance=estimate.published_covariance(covariance_inflation, carried),
                   fitness=estimate.signals.fitness,
                   accepted=estimate.accepted, latency_s=latency_s, n_points=n_points, reason=reason,
                   recovered=estimate.recovered, recovery_reason=recovery_reason, degenerate=estimate.degenerate,
                   signals=estimate.signals.as_dict(), origin=estimate.published_origin, polishes=polishes,
                   answer=None if estimate.signals.fitness == 0.0 else estimate.T_odom_sensor.copy())

    @classmethod
    def unregistered(cls, stamp_ns: int, pose: np.ndarray, *, accepted: bool, fitness: float, latency_s: float,
                     n_points: int, reason: str = "") -> AlignmentStep:
        """A scan that was not registered (the first of a trajectory, a duplicate stamp): ``pose`` kept, no
        relative motion, a zero covariance."""
        return cls(stamp_ns=stamp_ns, pose=pose.copy(), relative=None, covariance=flat_covariance(0.0, 0.0),
                   fitness=fitness, accepted=accepted, latency_s=latency_s, n_points=n_points, reason=reason)


@dataclass
class Estimate:
    """A registration and its verdict, before it is committed."""

    T_odom_sensor: np.ndarray
    covariance: np.ndarray
    signals: Signals
    failures: list[str]  # why it cannot be vouched for: the prediction is published instead
    notes: list[str]  # why it is flagged although its pose is used (degenerate, ambiguity resolved)
    recovered: bool
    free_directions: np.ndarray  # (6, k) normalised directions the scene leaves unconstrained
    length: float  # the lever arm of that normalisation
    origin: str = ""  # the kind of start it was polished from: cem, prediction, last pose, search
    tied: bool = False  # chosen among distinct near-ties (:mod:`.contest`): its pose is a guess among equals
    support: int = 1  # how many kinds of the competing starts reached this answer (:mod:`.contest`)
    explained: bool = False  # its polish converged within reach of the prediction (:mod:`.polish`)

    def offset_from(self, T_reference: np.ndarray) -> tuple[float, float]:
        """(metres, radians) from ``T_reference`` along the constrained directions only."""
        return disagreement(T_reference, keep_prediction_along(self.free_directions, self.length, T_reference,
                                                               self.T_odom_sensor))

    @property
    def degenerate(self) -> bool:
        return bool(self.notes)

    @property
    def accepted(self) -> bool:
        """A step the node vouches for: no failure and nothing to flag."""
        return not self.failures and not self.degenerate

    def published_covariance(self, inflation: float, carried: Optional[np.ndarray] = None) -> np.ndarray:
        """The covariance as published: this registration's plus ``carried`` (what the previous pose's error adds
        to the step, :func:`~.covariance.carried_into_step`), inflated when the step failed."""
        covariance = self.covariance if carried is None else self.covariance + carried
        return covariance * inflation if self.failures else covariance

    @property
    def published_origin(self) -> str:
        """The start of the published answer: none when the step failed (the prediction is published)."""
        return "" if self.failures else self.origin


class StepJudge:
    """Signals of one registration against the map, its failures, degeneracy and covariance."""

    def __init__(self, config: AlignerConfig, health: HealthMonitor) -> None:
        self.config = config
        self.health = health

    def judge(self, frame: Frame, target_map: VoxelMap, T_predicted: np.ndarray, T_start: np.ndarray,
              polish: PolishResult, spread_m: float, recovered: bool, prediction_std: float, origin: str
              ) -> Estimate:
        """The verdict on ``polish.T_target_source``, polished from ``T_start`` (``origin``: its kind; the
        disagreement signals say how far the polish moved it; ``spread_m``: the CEM's final spread when the CEM
        gave it); ``prediction_std`` (m) is the variance kept along unconstrained directions."""
        cfg = self.config.health
        T_final = polish.T_target_source
        conditioning = Conditioning.of(polish.hessian, frame.length)
        fitness, coverage = target_map.overlap(frame.polish, T_final, self.config.polish.inlier_distance
                                               * frame.polish_voxel, self.config.polish.inlier_residual,
                                               cfg.coverage_distance * frame.polish_voxel)
        metres, radians = disagreement(T_start, T_final)
        signals = Signals(fitness, metres, radians, conditioning.ratio, spread_m, coverage)
        failures = self.health.failures(signals)
        if polish.n_pairs < MIN_POLISH_PAIRS:
            failures.append(f"only {polish.n_pairs} point-to-plane pairs")
        notes = []
        if self.health.degenerate(signals):
            notes.append(f"degenerate (conditioning {conditioning.ratio:.4f}): the motion prediction kept along "
                         "the unconstrained direction")
            # The replacement is linear in the difference: a guess degrees away (a recovery's) would be meaningless.
            if not failures and disagreement(T_predicted, T_final)[1] < LINEAR_LIMIT:
                T_final = keep_prediction_along(conditioning.degenerate_basis(cfg.min_conditioning),
                                                conditioning.length, T_predicted, T_final)
        covariance = covariance_from_hessian(conditioning, polish.residual_variance, prediction_std ** 2,
                                             cfg.min_conditioning)
        return Estimate(T_final, covariance, signals, failures, notes, recovered,
                        conditioning.degenerate_basis(cfg.min_conditioning), conditioning.length, origin)

    def off_map(self, frame: Frame, T_guess: np.ndarray, what: str, margin: float) -> Estimate:
        """A failure: the map has too few points within the CEM's radius (+ ``margin`` m) of the ``what`` to
        register against (the step publishes the prediction, flagged; failures in a row restart the map)."""
        radius = self.config.preprocess.cem_radius * frame.scale + margin
        return Estimate(T_guess.copy(), flat_covariance(radius, np.pi), Signals(0.0, 0.0, 0.0, 0.0, 0.0),
                        [f"no map points within {radius:.1f} m of the {what}"], [], False, np.zeros((6, 0)), 1.0)
