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
  so nearness there would be no claim); and the running fitness **level** of the vouched steps;
- which starts have competed: the global **search** (independent of the prediction), the leader's rotational
  **neighbours** (its basin checked on a weakly constrained view);
- on demand, the share of the scan the leader puts **where the map's last scan saw empty space**
  (:mod:`~cemnet_ros.pipeline.map.free_space`; measured once, when first read: it costs a few milliseconds the
  cheap steps need not pay).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Callable, Optional, Sequence

import numpy as np

from cemnet_ros.pipeline.config import HealthConfig
from cemnet_ros.pipeline.steps.answer import Answer, Origin, distinct
from cemnet_ros.pipeline.steps.covariance import keep_prediction_along
from cemnet_ros.pipeline.steps.health import disagreement


@dataclass(frozen=True)
class Expectation:
    """What a scan's answers are judged against besides one another."""

    T_predicted: np.ndarray  # the motion model's pose (the guess, when the prediction left the map)
    near: tuple[float, float]  # (m, rad): how far from the prediction an answer is still the prediction's
    level: Optional[float]  # the running fitness of the vouched steps (None: none yet, e.g. the first pair)
    search_because: str = ""  # why the global search must compete whatever the answers ("": only if they need it)
    moving: bool = True  # the prediction extrapolates a motion (False: a first pair, a new target: none known)


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
    measure_seen_through: Callable[[Answer], float]  # an answer's share of the scan in the map's free space
    missing: str = ""

    @classmethod
    def of(cls, answers: Sequence[Answer], expectation: Expectation, rules: HealthConfig, *,
           support: Callable[[Answer], frozenset[Origin]], seen_through: Callable[[Answer], float],
           searched: bool, neighbours_checked: bool, missing: str = "") -> "Evidence":
        """The record of ``answers`` (see the module); ``support``: the kinds of start that reached an answer,
        ``seen_through``: the share of the scan an answer puts in the map's free space."""
        if not answers:
            return cls(expectation, None, (), None, frozenset(), (np.inf, np.inf), searched, neighbours_checked,
                       seen_through, missing)
        ranked = sorted(answers, key=lambda a: -a.consistency)
        best = ranked[0]
        margin = (1.0 - rules.tie_ratio) * best.fitness
        tied = [best]
        free = best.conditioning.degenerate_basis(rules.min_conditioning)
        for answer in ranked[1:]:
            T_constrained = keep_prediction_along(free, best.conditioning.length, best.T_odom_sensor,
                                                  answer.T_odom_sensor)  # its offset along free directions dropped
            if answer.consistency >= best.consistency - margin and all(
                    distinct(T_constrained, kept.T_odom_sensor) for kept in tied):
                tied.append(answer)
        offsets = [disagreement(expectation.T_predicted, a.T_odom_sensor) for a in tied]
        nearest = int(np.argmin([metres + a.conditioning.length * radians for a, (metres, radians)
                                 in zip(tied, offsets)]))
        leader = tied[nearest]
        rival = next((a for a in ranked if distinct(a.T_odom_sensor, leader.T_odom_sensor)), None)
        return cls(expectation, leader, tuple(tied) if len(tied) > 1 else (), rival, support(leader),
                   offsets[nearest], searched, neighbours_checked, seen_through, missing)

    @property
    def near(self) -> bool:
        """The leader lies within ``near`` of the prediction."""
        return self.offset[0] <= self.expectation.near[0] and self.offset[1] <= self.expectation.near[1]

    @property
    def expected(self) -> bool:
        """The prediction expects the leader (see the module)."""
        assert self.leader is not None
        return self.leader.explained or Origin.PREDICTION in self.support or self.near

    @cached_property
    def seen_through(self) -> float:
        """The share of the scan the leader puts where the map's last scan saw empty space."""
        assert self.leader is not None
        return self.measure_seen_through(self.leader)

    @property
    def margin(self) -> float:
        """The consistency the leader leads its rival by (inf: no rival)."""
        if self.leader is None or self.rival is None:
            return np.inf
        return self.leader.consistency - self.rival.consistency
