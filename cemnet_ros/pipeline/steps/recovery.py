"""Recovery (step 5 of the recipe in :mod:`..aligner`): the global CEM search when tracking cannot be trusted.

It runs on the first pair, when tracking failed or doubts its answer, or on request: the search
(:func:`~cemnet_ros.core.global_search.global_search`: yaw over the full circle, metres of translation, the tilt of
the guess; with ``recovery.scatter`` 'network' also candidates drawn from the sampling network's prior) returns
distinct hypotheses; each one close to the best in fitness enters tracking's contest (:mod:`.contest`), polished
wide. The last pose turned by a grid of yaws and tilts (:func:`turns`) enters too: a handheld sensor turns and
tilts tens of degrees between sparse scans, where the prediction, and the search around its tilt, are lost, and
the wide polish reaches the truth from a start within about 15 deg of it. Without tracking's answers the guess
itself (the motion prediction) and the last pose compete too: a distant hypothesis never replaces a near answer
of similar consistency, and distinct near-ties keep a symmetric scene from being published as a confident answer.
"""
from __future__ import annotations

import dataclasses
from typing import Optional

import numpy as np
import torch

from cemnet_ros.core import Registrar, RegistrationConfig
from cemnet_ros.core.config import GlobalSearchConfig
from cemnet_ros.core.geometry import apply_transform, turned_in_place
from cemnet_ros.core.global_search import SearchPrior, global_search
from cemnet_ros.core.registration import NETWORK_MIN_POINTS
from cemnet_ros.pipeline.config import AlignerConfig, RecoveryConfig
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.steps.contest import Contest, Origin
from cemnet_ros.pipeline.steps.frame import Frame
from cemnet_ros.pipeline.steps.metric_cem import EngineUnits
from cemnet_ros.pipeline.steps.polish import map_sample
from cemnet_ros.pipeline.steps.preprocess import subsample, voxel_downsample
from cemnet_ros.pipeline.steps.verdict import Estimate, StepJudge

POLISH_FRACTION = 0.8  # hypotheses whose CEM fitness is this close to the best one's get polished


def prior_registrar(config: AlignerConfig, given: Optional[Registrar] = None) -> Optional[Registrar]:
    """The registrar whose sampling network gives the recovery's prior: None unless ``recovery.scatter`` is
    'network'; then ``given``, or one loading ``recovery.weights``."""
    rec = config.recovery
    if rec.scatter != "network":
        return None
    return given or Registrar(RegistrationConfig(prior="network", weights=rec.weights, allow_pickle=rec.allow_pickle,
                                                 n_points=rec.points, device=config.registration.device))


def lean_search(search: GlobalSearchConfig, effort: float) -> GlobalSearchConfig:
    """The search's scatter and seeds scaled by ``effort`` (0, 1] (the hypotheses and their CEM kept)."""
    if effort >= 1.0:
        return search
    return dataclasses.replace(search, n_scatter=max(search.n_hypotheses, search.n_seeds,
                                                     round(effort * search.n_scatter)),
                               n_per_seed=round(effort * search.n_per_seed))


def turns(T_pose: np.ndarray, config: RecoveryConfig) -> list[np.ndarray]:
    """``T_pose`` turned about its own z axis by every ``recovery.turn_step`` up to ``recovery.turn_yaw`` either
    way, each also tilted by ``recovery.turn_tilt`` either way about its x and about its y axis (``T_pose`` itself
    excluded; none when ``turn_yaw`` is 0)."""
    if config.turn_yaw <= 0.0:
        return []
    n = int(config.turn_yaw // config.turn_step)
    yaws = np.radians(config.turn_step) * np.arange(-n, n + 1)
    tilt = np.radians(config.turn_tilt)
    tilts = [(0.0, 0.0)] + ([(tilt, 0.0), (-tilt, 0.0), (0.0, tilt), (0.0, -tilt)] if tilt > 0.0 else [])
    out = []
    for yaw in yaws:
        for pitch, roll in tilts:
            if yaw == 0.0 and pitch == 0.0 and roll == 0.0:
                continue
            out.append(turned_in_place(T_pose, np.array([yaw, pitch, roll])))
    return out


class Recovery:
    """The global search around a guess, its hypotheses polished and judged in the contest, the best chosen."""

    def __init__(self, config: AlignerConfig, judge: StepJudge, prior: Optional[Registrar] = None) -> None:
        self.config = config
        self.judge = judge
        self.prior = prior  # its network's mu0, sigma0 draw part of the scatter (None: uniform only)

    def recover(self, frame: Frame, target_map: VoxelMap, contest: Contest,
                T_fallback: Optional[np.ndarray] = None, T_last: Optional[np.ndarray] = None) -> Estimate:
        """The global CEM search around the contest's prediction (the guess), each hypothesis entering
        ``contest``, and the turns of ``T_last`` (the last pose); a contest without answers (tracking did not
        run) gets the polished guess and ``T_last`` itself too. The chosen answer fails unless it is confirmed
        (:meth:`~.health.HealthMonitor.unconfirmed`).

        ``T_fallback``: where to search instead when the map has no points near the guess (a wild prediction
        left the map: where the map last grew). The scan is placed at the guess and the engine's units are
        centred on the guessed sensor position, so that the search's yaw turns about the sensor and its
        translation disc is the sensor's displacement.
        """
        cfg, rec = self.config, self.config.recovery
        T_guess = contest.T_predicted
        target = map_sample(cfg, frame, target_map, T_guess, rec.points, margin=rec.radius)
        if len(target) < cfg.preprocess.min_points and T_fallback is not None:
            T_guess = T_fallback
            target = map_sample(cfg, frame, target_map, T_guess, rec.points, margin=rec.radius)
            if not contest.answers:
                contest = contest.recentred(T_guess)
        if len(target) < cfg.preprocess.min_points:
            return self.judge.off_map(frame, T_guess, "guess", rec.radius)
        units = EngineUnits(frame, T_guess[:3, 3])
        seed = max(cfg.registration.seed, 0)
        # The map holds at most a few points per map voxel: the scan, thinned alike, is sampled at the same density.
        uniform = voxel_downsample(frame.near, target_map.voxel_size)
        source = units.points(apply_transform(T_guess, subsample(uniform, rec.points, "random", seed)))
        target = units.points(target)
        hypotheses = global_search(source, target, np.zeros(6), rec.radius / frame.scale,
                                   lean_search(rec.search, contest.polisher.effort),
                                   seed=seed, prior=self._network_prior(source, target))
        contest.escalate(rec.radius)
        if not contest.answers:
            contest.enter(T_guess, Origin.PREDICTION, wide=True)
            if T_last is not None:
                contest.enter(T_last, Origin.LAST_POSE, wide=True)
        for hypothesis in hypotheses:
            if hypothesis.fitness < POLISH_FRACTION * hypotheses[0].fitness:
                break  # far behind the best: not worth a polish, nor a rival
            contest.enter(units.pose_in_metres(hypothesis.T_target_source) @ T_guess, Origin.SEARCH, wide=True)
        if T_last is not None and not self._settled(contest):
            for T_turned in turns(T_last, rec):
                contest.enter(T_turned, Origin.TURN, wide=True)
        chosen = contest.choose(rec.ambiguity_ratio)
        chosen.recovered = True  # this step ran the global search, whichever answer won
        why = self.judge.health.unconfirmed(chosen.signals.fitness, chosen.support,
                                            coverage=chosen.signals.coverage)
        if why and not chosen.failures:
            chosen.failures.append(why)
        return chosen

    def _settled(self, contest: Contest) -> bool:
        """The most consistent answer so far stands without the turns: no failure, confirmed by its fitness and
        covering the scan (the recovery, like tracking, stops at the first answer that stands)."""
        health = self.judge.health
        best = contest.ranked()[0] if contest.answers else None
        return best is not None and not best.failures and health.covers(best.signals.coverage) and not \
            health.unconfirmed(best.signals.fitness, 1)

    def _network_prior(self, source: np.ndarray, target: np.ndarray) -> Optional[SearchPrior]:
        """The network's raw mu0, sigma0 for the search's clouds in units (None: no network, or too few points)."""
        if self.prior is None or min(len(source), len(target)) < NETWORK_MIN_POINTS:
            return None
        clouds = (torch.as_tensor(cloud, dtype=torch.float32)[None] for cloud in (source, target))
        result = self.prior.register_batch(*clouds, run_cem=False)
        return SearchPrior(result.mu0[0], result.sigma0[0])
