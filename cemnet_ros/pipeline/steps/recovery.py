"""Recovery (step 5 of the recipe in :mod:`..aligner`): the global CEM search when tracking cannot be trusted.

It runs on the first pair, when tracking failed or is unconfirmed, or on request: the search
(:func:`~cemnet_ros.core.global_search.global_search`: yaw over the full circle, metres of translation; with
``recovery.prior`` 'network' also candidates drawn from the sampling network's prior) returns distinct
hypotheses; each one close to the best in fitness is polished and judged. The guess itself (the motion
prediction) and the last pose are polished too and compete with them (:mod:`.hypotheses`): a distant hypothesis
never replaces a near answer of similar fitness, and distinct near-ties keep a symmetric scene from being
published as a confident answer.
"""
from __future__ import annotations

from typing import Optional, Sequence

import numpy as np
import torch

from cemnet_ros.core import Registrar, RegistrationConfig
from cemnet_ros.core.geometry import apply_transform
from cemnet_ros.core.global_search import SearchPrior, global_search
from cemnet_ros.core.registration import NETWORK_MIN_POINTS
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.steps.adaptive import AdaptiveSpread
from cemnet_ros.pipeline.steps.frame import Frame
from cemnet_ros.pipeline.steps.hypotheses import choose
from cemnet_ros.pipeline.steps.preprocess import subsample, voxel_downsample
from cemnet_ros.pipeline.steps.tracking import PREDICTION_SPREADS, map_sample, wide_polish
from cemnet_ros.pipeline.steps.verdict import Estimate, StepJudge

POLISH_FRACTION = 0.8  # hypotheses whose CEM fitness is this close to the best one's get polished


def prior_registrar(config: AlignerConfig, given: Optional[Registrar] = None) -> Optional[Registrar]:
    """The registrar whose sampling network gives the recovery's prior: None unless ``recovery.prior`` is
    'network'; then ``given``, or one loading ``recovery.weights``."""
    rec = config.recovery
    if rec.prior != "network":
        return None
    return given or Registrar(RegistrationConfig(prior="network", weights=rec.weights, allow_pickle=rec.allow_pickle,
                                                 n_points=rec.points, device=config.registration.device))


class Recovery:
    """The global search around a guess, its hypotheses polished and judged, the best one chosen."""

    def __init__(self, config: AlignerConfig, spread: AdaptiveSpread, judge: StepJudge,
                 prior: Optional[Registrar] = None) -> None:
        self.config = config
        self.spread = spread
        self.judge = judge
        self.prior = prior  # its network's mu0, sigma0 draw part of the scatter (None: uniform only)

    def recover(self, frame: Frame, target_map: VoxelMap, T_guess: np.ndarray,
                T_fallback: Optional[np.ndarray] = None, T_last: Optional[np.ndarray] = None,
                rivals: Sequence[Estimate] = ()) -> Estimate:
        """The global CEM search around ``T_guess``, each distinct hypothesis polished, competing with
        ``rivals`` (tracking's answers) or, without them, the polished ``T_guess`` and ``T_last`` (the last
        pose). The chosen answer fails unless it is confirmed (:meth:`~.health.HealthMonitor.unconfirmed`).

        ``T_fallback``: where to search instead when the map has no points near the guess (a wild prediction
        left the map: where the map last grew). The scan is placed at the guess and the engine's units are
        centred on the guessed sensor position, so that the search's yaw turns about the sensor and its
        translation disc is the sensor's displacement.
        """
        cfg, rec = self.config, self.config.recovery
        target = map_sample(cfg, frame, target_map, T_guess, rec.points, margin=rec.radius)
        if len(target) < cfg.preprocess.min_points and T_fallback is not None:
            T_guess = T_fallback
            target = map_sample(cfg, frame, target_map, T_guess, rec.points, margin=rec.radius)
        if len(target) < cfg.preprocess.min_points:
            return self.judge.off_map(frame, T_guess, "guess", rec.radius)
        to_units, from_units = frame.network_units(T_guess[:3, 3])
        seed = max(cfg.registration.seed, 0)
        # The map holds at most a few points per map voxel: the scan, thinned alike, is sampled at the same density.
        uniform = voxel_downsample(frame.near, target_map.voxel_size)
        source = apply_transform(T_guess, subsample(uniform, rec.points, "random", seed))
        source_units, target_units = apply_transform(to_units, source), apply_transform(to_units, target)
        hypotheses = global_search(source_units, target_units, np.zeros(6), rec.radius / frame.scale, rec.search,
                                   seed=seed, prior=self._network_prior(source_units, target_units))
        T_local = [] if rivals else [(T_guess, "prediction")] + ([] if T_last is None else [(T_last, "last pose")])
        estimates = list(rivals) + [self._judged(frame, target_map, T_guess, T_start, origin)
                                    for T_start, origin in T_local]
        for hypothesis in hypotheses:
            if hypothesis.fitness < POLISH_FRACTION * hypotheses[0].fitness:
                break  # far behind the best: not worth a polish, nor a rival
            T_cem = from_units @ hypothesis.T_target_source @ to_units @ T_guess
            T_cem[3] = (0.0, 0.0, 0.0, 1.0)
            estimates.append(self._judged(frame, target_map, T_guess, T_cem, "search"))
        rotation, translation = self.spread.spread()
        near = (PREDICTION_SPREADS * translation, PREDICTION_SPREADS * rotation)
        chosen = choose(estimates, T_guess, rec.ambiguity_ratio, near)
        chosen.recovered = True  # this step ran the global search, whichever answer won
        why = self.judge.health.unconfirmed(chosen.signals.fitness, chosen.support)
        if why and not chosen.failures:
            chosen.failures.append(why)
        return chosen

    def _judged(self, frame: Frame, target_map: VoxelMap, T_guess: np.ndarray, T_start: np.ndarray,
                origin: str) -> Estimate:
        """The answer polished (widely: a start can be a metre or degrees off) from ``T_start``, judged."""
        polish = wide_polish(self.config, frame, target_map, T_start)
        return self.judge.judge(frame, target_map, T_guess, T_start, polish, 0.0, recovered=True,
                                prediction_std=self.config.recovery.radius, origin=origin)

    def _network_prior(self, source: np.ndarray, target: np.ndarray) -> Optional[SearchPrior]:
        """The network's raw mu0, sigma0 for the search's clouds in units (None: no network, or too few points)."""
        if self.prior is None or min(len(source), len(target)) < NETWORK_MIN_POINTS:
            return None
        clouds = (torch.as_tensor(cloud, dtype=torch.float32)[None] for cloud in (source, target))
        result = self.prior.register_batch(*clouds, run_cem=False)
        return SearchPrior(result.mu0[0], result.sigma0[0])
