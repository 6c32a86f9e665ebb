"""Tracking (step 3 of the recipe in :mod:`..aligner`): the polished prediction, else the CEM around it.

The prediction, finely polished against the map (point to plane), stands when the polish converged within its
pairing distance of the prediction and the answer is confirmed: the way a local method tracks. Otherwise the CEM
registers the frame's CEM subset against a sample of the map near the predicted sensor position, in network
units, with a spread that the recent prediction errors set (:class:`~.adaptive.AdaptiveSpread`); an answer
beyond the polish's reach of the prediction competes with the prediction and the last pose
(:mod:`.hypotheses`). :func:`map_sample` and :func:`wide_polish` serve the recovery too.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from cemnet_ros.core import Registrar
from cemnet_ros.core.geometry import apply_transform
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.steps.adaptive import AdaptiveSpread
from cemnet_ros.pipeline.steps.basin import gicp
from cemnet_ros.pipeline.steps.frame import Frame
from cemnet_ros.pipeline.steps.health import disagreement
from cemnet_ros.pipeline.steps.hypotheses import choose, distinct
from cemnet_ros.pipeline.steps.refine import PolishResult, point_to_plane_icp
from cemnet_ros.pipeline.steps.verdict import Estimate, StepJudge

PREDICTION_SPREADS = 3.0  # an answer further than this many tracking spreads is not explained by the prediction


def map_sample(config: AlignerConfig, frame: Frame, target_map: VoxelMap, T_guess: np.ndarray, n: int,
               margin: float = 0.0) -> np.ndarray:
    """``n`` map points within the CEM's radius (+ ``margin`` m) of the guessed sensor position."""
    radius = config.preprocess.cem_radius * frame.scale + margin
    return target_map.sample(n, T_guess[:3, 3], radius, seed=max(config.registration.seed, 0))


def fine_polish(config: AlignerConfig, frame: Frame, target_map: VoxelMap, T_start: np.ndarray) -> PolishResult:
    """The point-to-plane polish of every polish point against the map, pairs within two voxels: the precision."""
    return point_to_plane_icp(target_map, frame.polish, T_start, 2.0 * frame.polish_voxel, config.polish.iters)


def wide_polish(config: AlignerConfig, frame: Frame, target_map: VoxelMap, T_start: np.ndarray) -> PolishResult:
    """A polish from an answer that may be a metre or degrees off: GICP against the map's last scan first (it
    finds the basin, :mod:`.basin`), then :func:`fine_polish`."""
    T_basin = T_start
    if target_map.last_scan is not None:
        T_basin = gicp(target_map.last_scan, frame.gicp_cloud(target_map.voxel_size), T_start,
                       config.recovery.polish_distance * frame.polish_voxel, config.recovery.polish_iters)
    return fine_polish(config, frame, target_map, T_basin)


class Tracker:
    """Answers from the CEM around the prediction, the prediction and the last pose, polished and judged."""

    def __init__(self, config: AlignerConfig, registrar: Registrar, spread: AdaptiveSpread, judge: StepJudge) -> None:
        self.config = config
        self.registrar = registrar
        self.spread = spread
        self.judge = judge

    def track(self, frame: Frame, target_map: VoxelMap, T_predicted: np.ndarray, dt_ratio: float,
              T_last: Optional[np.ndarray]) -> tuple[Estimate, list[Estimate]]:
        """The registration of ``frame`` near ``T_predicted`` (``T_last``: the last pose; ``dt_ratio``: this time
        step over the usual one, which widens the CEM's spread).

        First the prediction, finely polished, as a local method would: it stands alone (:meth:`_stands_alone`)
        when it is confirmed and the polish converged within its reach of the prediction (the prediction was
        already in the right basin). Otherwise the CEM samples around the prediction; its answer, finely
        polished, stands alone on the same terms. Failing that, answers compete (:mod:`.hypotheses`): the CEM's
        and the prediction, each polished from afar, and, unless one of them stands alone, the last pose (a
        stop, a jerk, a turn reversed: the sensor did not move as it did). The fittest wins, near-ties go to the
        nearest (a direction the scene hardly constrains stays at the prediction). Returns the chosen answer and
        all of them (the recovery's rivals).
        """
        cfg = self.config
        rotation, translation = self.spread.spread(dt_ratio)

        def judged(polish: PolishResult, T_cem: np.ndarray, spread_m: float, origin: str) -> Estimate:
            return self.judge.judge(frame, target_map, T_predicted, T_cem, polish, spread_m, recovered=False,
                                    prediction_std=translation, origin=origin)

        if cfg.tracking.local_first:
            local = fine_polish(cfg, frame, target_map, T_predicted)
            predicted = judged(local, T_predicted, 0.0, "prediction")
            if self._stands_alone(frame, T_predicted, predicted, local):
                return predicted, [predicted]
        target = map_sample(cfg, frame, target_map, T_predicted, cfg.registration.n_points)
        if len(target) < cfg.preprocess.min_points:
            return self.judge.off_map(frame, T_predicted, "prediction", 0.0), []
        T_cem, spread_m = self._cem(frame, target, T_predicted, T_last, rotation, translation)
        cem_polish = fine_polish(cfg, frame, target_map, T_cem)
        usual = judged(cem_polish, T_cem, spread_m, "cem")
        if self._stands_alone(frame, T_predicted, usual, cem_polish):
            return usual, [usual]
        starts: list[np.ndarray] = []
        estimates: list[Estimate] = []
        standing: list[bool] = []

        def compete(T_start: np.ndarray, origin: str) -> None:
            if all(distinct(T_start, kept) for kept in starts):
                starts.append(T_start)
                polish = wide_polish(cfg, frame, target_map, T_start)
                estimates.append(judged(polish, T_cem, spread_m, origin))
                standing.append(self._stands_alone(frame, T_predicted, estimates[-1], polish))

        compete(T_cem, "cem")
        compete(T_predicted, "prediction")
        if T_last is not None and not any(standing):
            compete(T_last, "last pose")
        near = (PREDICTION_SPREADS * translation, PREDICTION_SPREADS * rotation)
        return choose(estimates, T_predicted, cfg.tracking.tie_ratio, near), estimates

    def doubts(self, estimate: Estimate, after_gap: bool = False) -> list[str]:
        """Why tracking's answer cannot stand without the global search (empty: it can): its failures, or it is
        unconfirmed (:meth:`~.health.HealthMonitor.unconfirmed`)."""
        if estimate.failures:
            return list(estimate.failures)
        why = self.judge.health.unconfirmed(estimate.signals.fitness, estimate.support, after_gap)
        return [why] if why else []

    def _stands_alone(self, frame: Frame, T_predicted: np.ndarray, estimate: Estimate, polish: PolishResult) -> bool:
        """No failure, confirmed without a second start (at ``health.confirm_ratio`` x the running level), and
        within the polish's reach of the prediction (:meth:`_within_reach`): fitness alone does not tell a
        wrong basin from the right one, so an answer the prediction does not explain needs rivals."""
        health = self.judge.health
        return (not estimate.failures and health.level is not None
                and not health.unconfirmed(estimate.signals.fitness, support=1)
                and self._within_reach(frame, T_predicted, polish))

    def _within_reach(self, frame: Frame, T_predicted: np.ndarray, polish: PolishResult) -> bool:
        """``polish`` converged, and its answer lies within the polish's pairing distance of the prediction
        (translation + lever arm x rotation): the prediction was in the basin the polish settled in, so the
        prediction and the answer cannot be two rival hypotheses."""
        if polish.iterations >= self.config.polish.iters:
            return False
        moved_m, moved_rad = disagreement(T_predicted, polish.T_target_source)
        return moved_m + frame.length * moved_rad <= 2.0 * frame.polish_voxel

    def _cem(self, frame: Frame, target: np.ndarray, T_predicted: np.ndarray, T_last: Optional[np.ndarray],
             rotation: float, translation: float) -> tuple[np.ndarray, float]:
        """The CEM in network units around the centre ``tracking.prior`` names (spread: the tracking spread, or
        ``tracking.identity_sigma``) against the map sample ``target``; (T_odom_sensor, final spread m)."""
        cfg = self.config
        to_units, from_units = frame.network_units(target.mean(axis=0))
        clouds = apply_transform(to_units, frame.sampled), apply_transform(to_units, target)
        T_centre = {"motion": T_predicted, "identity": T_last, "network": None}[cfg.tracking.prior]
        if T_centre is None:
            result = self.registrar.register(*clouds)
        else:
            sigma = (np.full(6, cfg.tracking.identity_sigma) if cfg.tracking.prior == "identity"
                     else np.r_[np.full(3, rotation), np.full(3, translation / frame.scale)])
            result = self.registrar.register(*clouds, prior_pose=to_units @ T_centre @ from_units,
                                             prior_sigma=sigma)
        T_cem = from_units @ np.asarray(result.transform, dtype=np.float64) @ to_units
        T_cem[3] = (0.0, 0.0, 0.0, 1.0)
        return T_cem, float(np.max(np.abs(result.sigma[3:]))) * frame.scale
