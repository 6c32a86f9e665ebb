"""Tracking (step 3 of the recipe in :mod:`..aligner`): the cheapest credible start first, stop once one stands.

An answer stands when it is confirmed and the prediction explains it, or it covers the scan (:mod:`.contest`).
The starts, in order:

1. **the prediction**, finely polished against the map, when its recent errors lie within the polish's reach
   (the way a local method tracks; smooth motion ends here);
2. **the prediction from afar**, polished wide (:mod:`.polish`: GICP, then fine): a handheld turn's prediction
   10-30 deg off usually lands in the truth's basin, and an answer that covers the scan stands;
3. **the CEM** around the prediction, in the engine's units (:mod:`.metric_cem`), against a sample of the map
   near the predicted sensor position, with a spread that the recent prediction errors set
   (:class:`~.adaptive.AdaptiveSpread`); its answer polished wide: it carries the steps the prediction cannot
   bridge, or confirms an answer that leaves part of the scan off the map (two kinds of start agree);
4. **the last pose from afar**; then the most consistent answer wins, near-ties go to the nearest.

With ``tracking.local_first`` false the CEM comes first on every step (the method alone), then 2 and 4.
"""
from __future__ import annotations

from functools import partial
from typing import Optional

import numpy as np

from cemnet_ros.core import Registrar
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.steps.adaptive import AdaptiveSpread
from cemnet_ros.pipeline.steps.contest import Contest, Origin
from cemnet_ros.pipeline.steps.frame import Frame
from cemnet_ros.pipeline.steps.metric_cem import EngineUnits
from cemnet_ros.pipeline.steps.polish import Polisher, map_sample
from cemnet_ros.pipeline.steps.verdict import Estimate, StepJudge

PREDICTION_SPREADS = 3.0  # an answer further than this many tracking spreads is not explained by the prediction
CREDIBLE_WINDOW = 10  # recent prediction errors that decide whether the prediction is polished first


class Tracker:
    """Answers from the prediction, the CEM around it and the last pose, polished, judged, competing."""

    def __init__(self, config: AlignerConfig, registrar: Registrar, spread: AdaptiveSpread, judge: StepJudge) -> None:
        self.config = config
        self.registrar = registrar
        self.spread = spread
        self.judge = judge

    def contest(self, frame: Frame, target_map: VoxelMap, T_predicted: np.ndarray, dt_ratio: float = 1.0,
                effort: float = 1.0) -> Contest:
        """An empty contest around ``T_predicted``: near is a few tracking spreads (``dt_ratio``: this time step
        over the usual one, which widens them); ``effort`` scales the polishes' budgets (:class:`.Polisher`)."""
        rotation, translation = self.spread.spread(dt_ratio)
        return Contest(Polisher(self.config, frame, target_map, effort), self.judge, T_predicted,
                       (PREDICTION_SPREADS * translation, PREDICTION_SPREADS * rotation), prediction_std=translation)

    def track(self, frame: Frame, target_map: VoxelMap, T_predicted: np.ndarray, dt_ratio: float,
              T_last: Optional[np.ndarray], effort: float = 1.0) -> tuple[Estimate, Contest]:
        """The registration of ``frame`` near ``T_predicted`` (``T_last``: the last pose); the answer and its
        contest (the recovery's rivals). See the module for the order of the starts and :meth:`contest` for
        ``dt_ratio`` and ``effort``."""
        cfg = self.config
        contest = self.contest(frame, target_map, T_predicted, dt_ratio, effort)
        if cfg.tracking.local_first and self._prediction_credible(contest.polisher, dt_ratio):
            contest.enter(T_predicted, Origin.PREDICTION)
            if (answer := contest.standing()) is not None:
                return answer, contest
        target = map_sample(cfg, frame, target_map, T_predicted, cfg.registration.n_points)
        if len(target) < cfg.preprocess.min_points:
            return self.judge.off_map(frame, T_predicted, "prediction", 0.0), contest
        from_afar = (partial(contest.enter, T_predicted, Origin.PREDICTION, wide=True),
                     partial(self._enter_cem, contest, target, T_predicted, T_last, dt_ratio))
        for enter in from_afar if cfg.tracking.local_first else reversed(from_afar):
            enter()
            if (answer := contest.standing()) is not None:
                return answer, contest
        if T_last is not None:
            contest.enter(T_last, Origin.LAST_POSE, wide=True)
        return contest.choose(cfg.tracking.tie_ratio), contest

    def doubts(self, estimate: Estimate, after_gap: bool = False) -> list[str]:
        """Why tracking's answer cannot stand without the global search (empty: it can): its failures, it is
        unconfirmed (:meth:`~.health.HealthMonitor.unconfirmed`), or one start alone reached it, the prediction
        does not explain it and it leaves part of the scan off the map (a wrong basin that fits well does)."""
        if estimate.failures:
            return list(estimate.failures)
        health, coverage = self.judge.health, estimate.signals.coverage
        why = health.unconfirmed(estimate.signals.fitness, estimate.support, after_gap, coverage)
        if not why and estimate.support < 2 and not estimate.explained and not health.covers(coverage):
            why = (f"partly off the map: coverage {coverage:.3f} < {health.config.confirm_coverage:.3f}, reached "
                   "from one start only")
        return [why] if why else []

    def _prediction_credible(self, polisher: Polisher, dt_ratio: float) -> bool:
        """The prediction is worth polishing on its own first: over the last ``CREDIBLE_WINDOW`` good steps its
        typical (median) error, translation + RMS range x rotation stretched by ``dt_ratio``, lay within the fine
        polish's reach (a handheld sensor's constant-velocity prediction is usually 10-30 deg off; a car's, or a
        sensor reversing now and then, usually within it). None recorded yet: not credible."""
        errors = self.spread.recent_errors(CREDIBLE_WINDOW)
        if not len(errors):
            return False
        typical = np.median(errors[:, 1] + polisher.frame.length * errors[:, 0]) * max(1.0, dt_ratio)
        return bool(typical <= polisher.reach)

    def _enter_cem(self, contest: Contest, target: np.ndarray, T_predicted: np.ndarray,
                   T_last: Optional[np.ndarray], dt_ratio: float) -> None:
        """The CEM's answer (:meth:`_cem`) polished wide in ``contest``."""
        T_cem, spread_m = self._cem(contest.polisher.frame, target, T_predicted, T_last, dt_ratio)
        contest.enter(T_cem, Origin.CEM, wide=True, spread_m=spread_m)

    def _cem(self, frame: Frame, target: np.ndarray, T_predicted: np.ndarray, T_last: Optional[np.ndarray],
             dt_ratio: float) -> tuple[np.ndarray, float]:
        """The CEM around the centre ``tracking.centre`` names (spread: the tracking spread, or
        ``tracking.identity_sigma``) against the map sample ``target``; (T_odom_sensor, final spread m)."""
        cfg = self.config
        units = EngineUnits(frame, target.mean(axis=0))
        clouds = units.points(frame.sampled), units.points(target)
        T_centre = {"motion": T_predicted, "identity": T_last, "network": None}[cfg.tracking.centre]
        if T_centre is None:
            result = self.registrar.register(*clouds)
        else:
            sigma = (np.full(6, cfg.tracking.identity_sigma) if cfg.tracking.centre == "identity"
                     else units.sigma(*self.spread.spread(dt_ratio)))
            result = self.registrar.register(*clouds, prior_pose=units.pose(T_centre), prior_sigma=sigma)
        return units.pose_in_metres(result.transform), float(np.max(np.abs(result.sigma[3:]))) * frame.scale
