"""What the decision reads about one scan (:mod:`.decision`), computed once from its answers: one frozen record.

- the **leader**: the most consistent answer; among distinct answers whose consistency falls short of the best
  one's by less than ``(1 - health.tie_ratio)`` x its fitness (a *near-tie*: the scene cannot settle them) the one
  nearest the prediction, so that a distant answer never replaces a near one of similar consistency. Answers that
  differ only along a direction the best one's view leaves free (a corridor's axis) are no near-tie: that is the
  view's degeneracy, which the decision handles as such;
- its **rival**: the most consistent answer distinct from it, and the **margin** it leads by;
- its **support**: the kinds of start that reached it;
- where it lies against the **expectation**: the prediction *expects* it when the prediction's own polish
  converged within reach of it, the prediction's start (fine or from afar) reached it, or it lies within
  ``near`` of the prediction (in every direction: along a direction the view leaves free an answer lies anywhere,
  so nearness there would be no claim); and the running **level** (fitness, coverage) of the vouched steps;
- which starts have competed: the global **search** (independent of the prediction), the leader's rotational
  **neighbours** (its basin checked on a weakly constrained view), the leader's own **wide polish** (where the
  map's last scan alone leads from it);
- which answers the map's last scan **saw through**: an answer that puts more of the scan where that scan saw
  empty space (:mod:`~cemnet_ros.pipeline.map.free_space`) than ``health.max_seen_through`` x its fitness (the
  share it puts on the map's surfaces) contradicts what the map saw, and does not compete (measured most
  consistent first, until one passes, and for its near-ties: a few milliseconds a scan). A wrong pose that fits
  the ground and a few walls (a car that "did not move" on a road) puts what the scan saw ahead inside what the
  map's scan saw through; fitness and coverage cannot tell it from the right one where the two views overlap
  little.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional, Sequence

import numpy as np

from cemnet_ros.pipeline.config import HealthConfig
from cemnet_ros.pipeline.steps.answer import Answer, Origin, distinct
from cemnet_ros.pipeline.steps.covariance import keep_prediction_along
from cemnet_ros.pipeline.steps.health import Level, disagreement


@dataclass(frozen=True)
class Expectation:
    """What a scan's answers are judged against besides one another."""

    T_predicted: np.ndarray  # the motion model's pose (the guess, when the prediction left the map)
    near: tuple[float, float]  # (m, rad): how far from the prediction an answer is still the prediction's
    level: Optional[Level]  # the running fitness and coverage of the vouched steps (None: none yet, a first pair)
    search_because: str = ""  # why the global search must compete whatever the answers ("": only if they need it)
    moving: bool = True  # the prediction extrapolates a motion (False: a first pair, a new target: none known)
    reach: float = np.inf  # m: how far the fine polish reaches; a leader farther from the predicted position slid


@dataclass(frozen=True)
class Evidence:
    """One scan's answers as the decision sees them (see the module)."""

    expectation: Expectation
    leader: Optional[Answer]  # None: no answer at all (``missing`` says why)
    tied: tuple[Answer, ...]  # the distinct near-ties, the leader among them (empty: no near-tie)
    rival: Optional[Answer]  # the most consistent answer distinct from the leader
    support: frozenset[Origin]  # the kinds of start that reached the leader
    offset: tuple[float, float]  # (m, rad) of the leader from the prediction
    searched: bool  # the global search's hypotheses have competed
    neighbours_checked: bool  # the leader's rotational neighbours have competed
    last_scan_checked: bool  # the leader has been reviewed from the map's last scan (its own wide polish)
    contradicted: tuple[Answer, ...] = ()  # answers dropped: the map's last scan saw through them
    missing: str = ""

    @classmethod
    def of(cls, answers: Sequence[Answer], expectation: Expectation, rules: HealthConfig, *,
           support: Callable[[Answer], frozenset[Origin]], seen_through: Callable[[Answer], float],
           searched: bool, neighbours_checked: bool, last_scan_checked: Callable[[Answer], bool],
           missing: str = "") -> "Evidence":
        """The record of ``answers`` (see the module); ``support``: the kinds of start that reached an answer,
        ``seen_through``: the share of the scan an answer puts in the free space of the map's last scan,
        ``last_scan_checked``: an answer has been reviewed from the map's last scan."""
        def contradicts(answer: Answer) -> bool:
            return seen_through(answer) > rules.max_seen_through * answer.fitness

        ranked = sorted(answers, key=lambda a: -a.consistency)
        contradicted: list[Answer] = []
        while ranked and contradicts(ranked[0]):
            contradicted.append(ranked.pop(0))
        if not ranked:
            if contradicted:
                first = contradicted[0]
                missing = (f"every answer puts more of the scan where the map's last scan saw empty space than "
                           f"{rules.max_seen_through:.2f} x its fitness (the most consistent: "
                           f"{seen_through(first):.3f} against fitness {first.fitness:.3f})")
            return cls(expectation, None, (), None, frozenset(), (np.inf, np.inf), searched, neighbours_checked,
                       False, tuple(contradicted), missing)
        best = ranked[0]
        margin = (1.0 - rules.tie_ratio) * best.fitness
        tied = [best]
        free = best.conditioning.degenerate_basis(rules.min_conditioning)
        for answer in ranked[1:]:
            T_constrained = keep_prediction_along(free, best.conditioning.length, best.T_odom_sensor,
                                                  answer.T_odom_sensor)  # its offset along free directions dropped
            if answer.consistency >= best.consistency - margin and all(
                    distinct(T_constrained, kept.T_odom_sensor) for kept in tied):
                if contradicts(answer):
                    contradicted.append(answer)
                else:
                    tied.append(answer)
        offsets = [disagreement(expectation.T_predicted, a.T_odom_sensor) for a in tied]
        nearest = int(np.argmin([metres + a.conditioning.length * radians for a, (metres, radians)
                                 in zip(tied, offsets)]))
        leader = tied[nearest]
        rival = next((a for a in ranked if not any(a is c for c in contradicted)
                      and distinct(a.T_odom_sensor, leader.T_odom_sensor)), None)  # a competitor, distinct
        return cls(expectation, leader, tuple(tied) if len(tied) > 1 else (), rival, support(leader),
                   offsets[nearest], searched, neighbours_checked, last_scan_checked(leader), tuple(contradicted),
                   missing)

    @property
    def near(self) -> bool:
        """The leader lies within ``near`` of the prediction."""
        return self.offset[0] <= self.expectation.near[0] and self.offset[1] <= self.expectation.near[1]

    @property
    def expected(self) -> bool:
        """The prediction expects the leader (see the module)."""
        assert self.leader is not None
        return self.leader.explained or Origin.PREDICTION in self.support or self.near

    @property
    def displaced(self) -> bool:
        """The leader lies farther from the predicted position than the fine polish reaches, along a known motion:
        its rotation at the predicted position has a basin of its own to check (a slide along a weakly
        constrained direction keeps the right rotation)."""
        return self.expectation.moving and self.offset[0] > self.expectation.reach

    @property
    def outranked(self) -> bool:
        """An answer more consistent than the leader was dropped: the map's last scan saw through it."""
        assert self.leader is not None
        return any(answer.consistency > self.leader.consistency for answer in self.contradicted)

    @property
    def disputed(self) -> bool:
        """The leader's own review from the map's last scan led to a distinct answer (the map and the scan it took
        in last disagree on it)."""
        return self.last_scan_checked and Origin.LAST_SCAN not in self.support

    @property
    def margin(self) -> float:
        """The consistency the leader leads its rival by (inf: no rival)."""
        if self.leader is None or self.rival is None:
            return np.inf
        return self.leader.consistency - self.rival.consistency
