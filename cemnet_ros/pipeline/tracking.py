"""Tracking (step 3 of the recipe in :mod:`.aligner`): the CEM around the motion prediction, then the polish.

The CEM registers the frame's CEM subset against a sample of the map near the predicted sensor position, in
network units, with a spread that the recent prediction errors set (:class:`~.adaptive.AdaptiveSpread`). The
point-to-plane polish against the map itself brings the precision. :func:`map_sample` and :func:`wide_polish`
serve the recovery too.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from cemnet_ros.core import Registrar
from cemnet_ros.core.geometry import apply_transform
from cemnet_ros.pipeline.adaptive import AdaptiveSpread
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.frame import Frame
from cemnet_ros.pipeline.health import disagreement
from cemnet_ros.pipeline.refine import PolishResult, point_to_plane_icp
from cemnet_ros.pipeline.verdict import Estimate, StepJudge
from cemnet_ros.pipeline.voxel_map import VoxelMap

TRACKING_PAIRING = 3.0  # frame voxels: the tracking polish pairs within the adaptive spread, at most this far
PREDICTION_SPREADS = 3.0  # an answer further than this many tracking spreads is not explained by the prediction


def map_sample(config: AlignerConfig, frame: Frame, target_map: VoxelMap, T_guess: np.ndarray, n: int,
               margin: float = 0.0) -> np.ndarray:
    """``n`` map points within the CEM's radius (+ ``margin`` m) of the guessed sensor position."""
    radius = config.preprocess.cem_radius * frame.scale + margin
    return target_map.sample(n, T_guess[:3, 3], radius, seed=max(config.registration.seed, 0))


def wide_polish(config: AlignerConfig, frame: Frame, target_map: VoxelMap, T_start: np.ndarray) -> PolishResult:
    """A polish from an answer that may be a metre or degrees off: wide pairing first, then the fine one."""
    rec, voxel = config.recovery, frame.polish_voxel
    coarse = point_to_plane_icp(target_map, frame.polish, T_start, rec.polish_distance * voxel, rec.polish_iters)
    return point_to_plane_icp(target_map, frame.polish, coarse.T_target_source, 2.0 * voxel, config.polish.iters)


class Tracker:
    """The CEM around the prediction (adaptive spread) against a map sample, then the polish, judged."""

    def __init__(self, config: AlignerConfig, registrar: Registrar, spread: AdaptiveSpread, judge: StepJudge) -> None:
        self.config = config
        self.registrar = registrar
        self.spread = spread
        self.judge = judge

    def track(self, frame: Frame, target_map: VoxelMap, T_predicted: np.ndarray, dt_ratio: float,
              T_last: Optional[np.ndarray]) -> Estimate:
        """The registration of ``frame`` near ``T_predicted`` (``T_last``: the last pose, the identity prior's
        centre; ``dt_ratio``: this time step over the usual one, which widens the spread).

        When CEM and polish disagree the CEM gets a second opinion around the polish's answer: a prediction
        that was far off (a stop, a swing) leaves the first search looking in the wrong place, a polish that
        slid away finds no consensus there.
        """
        cfg = self.config
        target = map_sample(cfg, frame, target_map, T_predicted, cfg.registration.n_points)
        if len(target) < cfg.preprocess.min_points:
            return self.judge.off_map(frame, T_predicted, "prediction", 0.0)
        to_units, from_units = frame.network_units(target.mean(axis=0))
        clouds = apply_transform(to_units, frame.sampled), apply_transform(to_units, target)
        rotation, translation = self.spread.spread(dt_ratio)
        sigma = (np.full(6, cfg.tracking.identity_sigma) if cfg.tracking.prior == "identity"
                 else np.r_[np.full(3, rotation), np.full(3, translation / frame.scale)])
        centre = {"motion": T_predicted, "identity": T_last, "network": None}[cfg.tracking.prior]
        T_cem, spread_m = self._cem(frame, clouds, to_units, from_units, centre, sigma)
        voxel = frame.polish_voxel
        max_distance = float(np.clip(translation, 2.0 * voxel, TRACKING_PAIRING * voxel))
        polish = point_to_plane_icp(target_map, frame.polish, T_cem, max_distance, cfg.polish.iters)
        metres, radians = disagreement(T_predicted, polish.T_target_source)
        if metres > PREDICTION_SPREADS * translation or radians > PREDICTION_SPREADS * rotation:  # look wider
            polish = wide_polish(cfg, frame, target_map, polish.T_target_source)
        metres, radians = disagreement(T_cem, polish.T_target_source)
        if self.judge.health.disagree(metres, radians, self.judge.resolution(frame)):
            T_cem, spread_m = self._cem(frame, clouds, to_units, from_units, polish.T_target_source, sigma)
        return self.judge.judge(frame, target_map, T_predicted, T_cem, polish, spread_m, recovered=False,
                                prediction_std=translation)

    def _cem(self, frame: Frame, clouds: tuple[np.ndarray, np.ndarray], to_units: np.ndarray,
             from_units: np.ndarray, T_centre: Optional[np.ndarray], sigma: np.ndarray) -> tuple[np.ndarray, float]:
        """The CEM in units around ``T_centre`` (None: the network's prior); (T_odom_sensor, final spread m)."""
        if T_centre is None:
            result = self.registrar.register(*clouds)
        else:
            result = self.registrar.register(*clouds, prior_pose=to_units @ T_centre @ from_units,
                                             prior_sigma=sigma)
        T_cem = from_units @ np.asarray(result.transform, dtype=np.float64) @ to_units
        T_cem[3] = (0.0, 0.0, 0.0, 1.0)
        return T_cem, float(np.max(np.abs(result.sigma[3:]))) * frame.scale
