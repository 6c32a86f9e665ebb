"""Registering one frame against one map (steps 3 to 5 of the recipe in :mod:`..aligner`): the plan's starts
(:mod:`.starts`), cheapest first, each polished and measured (:mod:`.answer`), until the decision
(:mod:`.decision`) on their evidence (:mod:`.evidence`) settles; then the pose and covariance to publish.

One loop for tracking and recovery: the global search is the plan's fifth stage, reached when no cheaper answer
stands (or at once where the caller says why). Within a live scan's budget (:mod:`.scan_budget`) the long stages
run only where they fit; an answer that waited for them is then *unconfirmed*. Sequential mode (:mod:`..aligner`)
and pair mode (:mod:`..pair_mode`) register through it alike; what they commit differs.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Optional

import numpy as np

from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.steps.adaptive import AdaptiveSpread
from cemnet_ros.pipeline.steps.contest import Contest
from cemnet_ros.pipeline.steps.covariance import covariance_from_hessian, flat_covariance
from cemnet_ros.pipeline.steps.decision import Needs, Outcome, Verdict, decide, weak_view
from cemnet_ros.pipeline.steps.evidence import Evidence
from cemnet_ros.pipeline.steps.frame import Frame
from cemnet_ros.pipeline.steps.health import Level
from cemnet_ros.pipeline.steps.metric_cem import MetricEngine
from cemnet_ros.pipeline.steps.polish import Polisher
from cemnet_ros.pipeline.steps.scan_budget import ScanBudget, StageCosts
from cemnet_ros.pipeline.steps.starts import Stage, Starts

PREDICTION_SPREADS = 3.0  # an answer within this many tracking spreads of the prediction is the prediction's
EARLY = (Outcome.ACCEPTED, Outcome.DEGENERATE)  # end the plan before its end: more starts only add rivals


@dataclass(frozen=True)
class Registered:
    """A frame's registration, before it is committed: the verdict, the evidence it was decided on, the pose a
    step that is not failed publishes (the leader, as registered), its covariance (ROS order; a failed step's
    inflated by the committer), whether the global search ran and why, and the polishes it cost."""

    verdict: Verdict
    evidence: Evidence
    T_odom_sensor: Optional[np.ndarray]  # None: no answer at all
    covariance: np.ndarray
    searched: bool
    why_searched: str
    polishes: int

    @property
    def answer(self) -> Optional[np.ndarray]:
        """The leading answer's pose, as registered (None: none)."""
        leader = self.evidence.leader
        return None if leader is None else leader.T_odom_sensor


class Registration:
    """The plan run against one map until the decision settles (see the module)."""

    def __init__(self, config: AlignerConfig, engine: MetricEngine, spread: AdaptiveSpread) -> None:
        self.config, self.engine, self.spread = config, engine, spread
        self.stage_costs = StageCosts()  # what the long stages cost on this machine (a live scan's budget reads it)

    def register(self, frame: Frame, target_map: VoxelMap, T_predicted: np.ndarray, *, level: Optional[Level],
                 search_because: str = "", T_last: Optional[np.ndarray] = None, dt_ratio: float = 1.0,
                 effort: float = 1.0, moving: bool = True, T_fallback: Optional[np.ndarray] = None,
                 budget: Optional[ScanBudget] = None) -> Registered:
        """``frame`` registered against ``target_map`` near ``T_predicted``.

        ``level``: the running fitness and coverage of the vouched steps (None: none); ``search_because``: why the
        global search must compete whatever tracking finds; ``T_last``: the last pose; ``dt_ratio``: this time step
        over the usual one (it widens the prediction's spread); ``effort`` (0, 1]: the share of the polishes' and
        the search's budgets (a live node behind its input); ``moving``: the prediction extrapolates a known motion
        (False: the first pair); ``T_fallback``: where to search when the map has no points near the prediction;
        ``budget``: a live scan's time (None: the whole plan runs, as offline).
        """
        contest = Contest(Polisher(self.config, frame, target_map, effort), T_predicted)
        starts = Starts(self.config, self.engine, self.spread, dt_ratio, T_last, T_fallback)
        rotation, translation = self.spread.spread()  # not stretched by a gap: "near" must stay a claim
        near = (PREDICTION_SPREADS * translation, PREDICTION_SPREADS * rotation)
        long_stages: dict[Stage, str] = {starts.search: "search", starts.turns: "turns"}
        searched_first = bool(search_because) and (budget is None or budget.fits("search"))
        stages = starts.plan(contest, searched_first=searched_first)
        evidence, verdict, why, left_out = None, None, search_because, ""
        while verdict is None or verdict.outcome not in EARLY:
            if verdict is not None and verdict.needs in (Needs.NEIGHBOURS, Needs.LAST_SCAN):
                assert evidence is not None and evidence.leader is not None  # a verdict that needs them has one
                if verdict.needs == Needs.LAST_SCAN:
                    contest.review(evidence.leader)
                else:
                    starts.neighbours(contest, evidence.leader, turned=weak_view(evidence.leader, self.config.health),
                                      at_prediction=evidence.displaced)
            elif stages:
                stage, name = stages[0], long_stages.get(stages[0], "")
                promised = searched_first and stage == starts.search  # it fitted when the plan was made
                if name and budget is not None and verdict is not None and not promised and not budget.fits(name):
                    left_out = budget.shortfall(name)
                    break
                if verdict is not None and not why and stage == starts.search:
                    why = f"tracking failed ({verdict.reason})"
                started = time.perf_counter()
                stages.pop(0)(contest)
                if name:
                    self.stage_costs.record(name, time.perf_counter() - started)
            else:
                break
            evidence = contest.evidence(near, level, self.config.health, search_because, moving)
            verdict = decide(evidence, self.config.health)
        assert evidence is not None and verdict is not None  # every plan has a stage
        if left_out and verdict.outcome == Outcome.UNSETTLED:  # rule 1 passed: the leader overlaps
            if evidence.tied and not evidence.near:  # as after the search: equals, none next to the prediction
                verdict = Verdict(Outcome.AMBIGUOUS, f"ambiguous ({verdict.reason}), none next to the motion "
                                                     f"prediction: {left_out}")
            else:
                verdict = Verdict(Outcome.UNCONFIRMED, f"unconfirmed ({verdict.reason}): {left_out}")
        prediction_std = self.config.recovery.radius if contest.searched else translation
        published = self._published(evidence, prediction_std, contest.polisher.frame)
        return Registered(verdict, evidence, *published, contest.searched, why if contest.searched else "",
                          contest.polishes)

    def _published(self, evidence: Evidence, prediction_std: float, frame: Frame
                   ) -> tuple[Optional[np.ndarray], np.ndarray]:
        """The pose a step that is not failed publishes (the leader as registered: along a weakly constrained
        direction too, where the scan's weak pull lands nearer the truth than the prediction, see
        :mod:`.decision` rule 8), and the registration's covariance; the free directions keep the prediction's
        variance (``prediction_std`` m)."""
        leader, rules = evidence.leader, self.config.health
        if leader is None:
            return None, flat_covariance(self.config.preprocess.cem_radius * frame.scale + prediction_std, np.pi)
        covariance = covariance_from_hessian(leader.conditioning, leader.residual_variance, prediction_std ** 2,
                                             rules.min_conditioning)
        return leader.T_odom_sensor, covariance
