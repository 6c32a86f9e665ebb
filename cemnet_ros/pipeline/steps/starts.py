"""The starts a scan's answers are polished from, cheapest first: the plan :mod:`.registration` runs until the
decision settles (steps 3 and 5 of the recipe in :mod:`..aligner`).

1. **the prediction**, finely polished against the map, when its recent errors lie within the polish's reach
   (the way a local method tracks; smooth motion ends here);
2. **the prediction from afar**, polished wide (:mod:`.polish`: GICP, then fine): a handheld turn's prediction
   10-30 deg off usually lands in the truth's basin;
3. **the CEM** around the prediction, in the engine's units (:class:`~.metric_cem.MetricEngine`), against a
   sample of the map near the predicted sensor position, with a spread that the recent prediction errors set
   (:class:`~.adaptive.AdaptiveSpread`); its answer polished wide: it carries the steps the prediction cannot
   bridge;
4. **the last pose from afar**: the sensor did not move as it did (a stop, a jerk, a turn reversed);
5. **the global search** around the prediction (yaw over the full circle, ``recovery.radius`` m of translation;
   around where the map last grew when the prediction left the map), its hypotheses polished wide: starts
   independent of the prediction;
6. **the turns of the last pose** (:func:`turns`): a handheld sensor turns and tilts tens of degrees between
   sparse scans, where the prediction, and the search around its tilt, are lost; the wide polish reaches the
   truth from a start within about 15 deg of it;
7. **the leader's neighbours** (on demand): the leading answer turned by the fine polish's reach either way about
   the sensor's z axis, where its view is weakly constrained (a flat valley of a narrow field of view), and its
   rotation at the predicted position, where it lies beyond the fine polish's reach of it (a slide).

With ``tracking.local_first`` false the CEM comes first (the method alone), before 2 and 4. A step the caller
sends to the search (the first pair, after a failed step, on request) skips 1 and 3.
"""
from __future__ import annotations

from typing import Callable, Optional

import numpy as np

from cemnet_ros.core.geometry import turned_in_place
from cemnet_ros.pipeline.config import AlignerConfig, RecoveryConfig
from cemnet_ros.pipeline.steps.adaptive import AdaptiveSpread
from cemnet_ros.pipeline.steps.answer import Answer, Origin
from cemnet_ros.pipeline.steps.contest import Contest
from cemnet_ros.pipeline.steps.metric_cem import MetricEngine
from cemnet_ros.pipeline.steps.polish import map_sample

CREDIBLE_WINDOW = 10  # recent prediction errors that decide whether the prediction is polished first

Stage = Callable[[Contest], None]


def turns(T_pose: np.ndarray, config: RecoveryConfig) -> list[np.ndarray]:
    """``T_pose`` turned about its own z axis by every ``recovery.turn_step_deg`` up to ``recovery.turn_yaw_deg``
    either way, each also tilted by ``recovery.turn_tilt_deg`` either way about its x and about its y axis
    (``T_pose`` itself excluded; none when ``turn_yaw_deg`` is 0)."""
    if config.turn_yaw_deg <= 0.0:
        return []
    n = int(config.turn_yaw_deg // config.turn_step_deg)
    yaws = np.radians(config.turn_step_deg) * np.arange(-n, n + 1)
    tilt = np.radians(config.turn_tilt_deg)
    tilts = [(0.0, 0.0)] + ([(tilt, 0.0), (-tilt, 0.0), (0.0, tilt), (0.0, -tilt)] if tilt > 0.0 else [])
    out = []
    for yaw in yaws:
        for pitch, roll in tilts:
            if yaw == 0.0 and pitch == 0.0 and roll == 0.0:
                continue
            out.append(turned_in_place(T_pose, np.array([yaw, pitch, roll])))
    return out


class Starts:
    """The stages of one scan's plan (see the module), each entering its starts into the contest."""

    def __init__(self, config: AlignerConfig, engine: MetricEngine, spread: AdaptiveSpread, dt_ratio: float,
                 T_last: Optional[np.ndarray], T_fallback: Optional[np.ndarray]) -> None:
        """``dt_ratio``: this time step over the usual one (it widens the CEM's spread); ``T_last``: the last
        pose; ``T_fallback``: where to search when the map has no points near the prediction (where it last
        grew)."""
        self.config, self.engine, self.spread, self.dt_ratio = config, engine, spread, dt_ratio
        self.T_last, self.T_fallback = T_last, T_fallback

    def plan(self, contest: Contest, searched_first: bool) -> list[Stage]:
        """The stages in order (``searched_first``: the caller sends the scan to the search: no 1 and 3)."""
        tracking = [self.prediction_from_afar, self.cem]
        if not self.config.tracking.local_first:
            tracking.reverse()
        elif self.prediction_credible(contest):
            tracking.insert(0, self.prediction)
        if searched_first:
            tracking = [self.prediction_from_afar]
        return [*tracking, self.last_pose, self.search, self.turns]

    def prediction_credible(self, contest: Contest) -> bool:
        """The prediction is worth polishing on its own first: over the last ``CREDIBLE_WINDOW`` good steps its
        typical (median) error, translation + RMS range x rotation stretched by ``dt_ratio``, lay within the fine
        polish's reach (a handheld sensor's constant-velocity prediction is usually 10-30 deg off; a car's, or a
        sensor reversing now and then, usually within it). None recorded yet: not credible."""
        errors = self.spread.recent_errors(CREDIBLE_WINDOW)
        if not len(errors):
            return False
        polisher = contest.polisher
        typical = np.median(errors[:, 1] + polisher.frame.length * errors[:, 0]) * max(1.0, self.dt_ratio)
        return bool(typical <= polisher.reach)

    def prediction(self, contest: Contest) -> None:
        contest.enter(contest.T_predicted, Origin.PREDICTION)

    def prediction_from_afar(self, contest: Contest) -> None:
        contest.enter(contest.T_predicted, Origin.PREDICTION, wide=True)

    def cem(self, contest: Contest) -> None:
        """The CEM around ``tracking.centre`` (the prediction, the last pose or the network's mu0), against a map
        sample near the predicted sensor position; nothing there: the contest says so."""
        cfg, frame = self.config, contest.polisher.frame
        target = map_sample(cfg, frame, contest.polisher.map, contest.T_predicted, cfg.registration.n_points)
        if len(target) < cfg.preprocess.min_points:
            contest.missing = f"no map points within {cfg.preprocess.cem_radius * frame.scale:.1f} m of the prediction"
            return
        centre = cfg.tracking.centre
        T_centre = {"motion": contest.T_predicted, "identity": self.T_last, "network": None}[centre]
        sigma = self.spread.spread(self.dt_ratio) if centre == "motion" else None
        T_cem, spread_m = self.engine.cem(frame, target, T_centre, sigma)
        contest.enter(T_cem, Origin.CEM, wide=True, spread_m=spread_m)

    def last_pose(self, contest: Contest) -> None:
        if self.T_last is not None:
            contest.enter(self.T_last, Origin.LAST_POSE, wide=True)

    def search(self, contest: Contest) -> None:
        """The global search around the prediction (around the fallback when the map has no points near it),
        its hypotheses polished wide."""
        cfg, rec, polisher = self.config, self.config.recovery, contest.polisher
        T_guess = contest.T_predicted
        target = map_sample(cfg, polisher.frame, polisher.map, T_guess, rec.points, margin=rec.radius)
        if len(target) < cfg.preprocess.min_points and self.T_fallback is not None:
            T_guess = self.T_fallback
            target = map_sample(cfg, polisher.frame, polisher.map, T_guess, rec.points, margin=rec.radius)
            if not contest.answers:
                contest.recentre(T_guess)
        contest.searched = True
        if len(target) < cfg.preprocess.min_points:
            radius = cfg.preprocess.cem_radius * polisher.frame.scale + rec.radius
            contest.missing = f"no map points within {radius:.1f} m of the guess"
            return
        for T_hypothesis in self.engine.search(polisher.frame, target, polisher.map.voxel_size, T_guess,
                                               polisher.effort):
            contest.enter(T_hypothesis, Origin.SEARCH, wide=True)

    def turns(self, contest: Contest) -> None:
        if self.T_last is not None:
            for T_turned in turns(self.T_last, self.config.recovery):
                contest.enter(T_turned, Origin.TURN, wide=True)

    def neighbours(self, contest: Contest, leader: Answer, *, turned: bool, at_prediction: bool) -> None:
        """The leader's neighbours: ``turned`` by the fine polish's reach either way about the sensor's z axis (a
        weakly constrained view), and ``at_prediction``: its rotation at the predicted position (a leader that
        slid beyond the fine polish's reach of it)."""
        T_leader = leader.T_odom_sensor
        if turned:
            reach = contest.polisher.reach_rad
            for sign in (1.0, -1.0):
                contest.enter(turned_in_place(T_leader, np.array([sign * reach, 0.0, 0.0])), Origin.NEIGHBOUR)
        if at_prediction:
            T_moved = T_leader.copy()
            T_moved[:3, 3] = contest.T_predicted[:3, 3]
            contest.enter(T_moved, Origin.NEIGHBOUR)
        contest.neighbours_checked = True
