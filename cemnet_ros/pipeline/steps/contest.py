"""One scan's competing answers (tracking's and the recovery's): polish a start, judge it, does it stand, choose.

Every start (:class:`Origin`) is polished (:mod:`.polish`) and judged (:mod:`.verdict`). Answers closer than
the precision the node vouches for (``DISTINCT_M``, ``DISTINCT_RAD``: metres and radians, whatever the scene's
size or the auto scale) are one answer; the kinds of start that reached it are its *support*. A wide polish
whose basin stage lands on an answer already there adds its support and is not polished again.

Answers rank by their *consistency* with the map (:attr:`~.health.Signals.consistency`: the share of the scan on
the map's surfaces less the share where the map has none). Fitness alone does not tell a wrong basin from the
right one in a regular building: a pose turned by 90 deg or shifted by a room fits the walls about as well as the
truth, but leaves part of the scan in empty space.

An answer **stands** (the scan needs no further start) when it has no failure, fits at ``health.confirm_ratio`` x
the running level, and the prediction explains it: its polish converged within reach of the prediction, or it
lies within the prediction's spread (``near``) and either two kinds of start reached it or it covers the scan
(``health.confirm_coverage``: the evidence a wrong basin lacks, above). Any other answer needs rivals.

An accepted answer on a weakly constrained view (conditioning below ``health.neighbour_conditioning``: a narrow
field of view, where the polish stops anywhere along a flat valley) is **checked against its neighbours**
(:meth:`Contest.checked_against_neighbours`): polished again from its pose turned by the fine polish's reach
either way about the sensor's z axis; a distinct neighbour about as consistent flags it (a near-tie), a clearly
more consistent one replaces it.

When none stands, the most consistent answer wins; distinct answers whose consistency falls short of the best
one's by less than ``1 - tie_ratio`` of its fitness are a near-tie the scene cannot settle: the one next to the
prediction is kept and flagged (a symmetric scene; the map does not take it in), and when none is next to it the
step fails as ambiguous. A distant answer never replaces a near one of similar consistency. The global search's
hypotheses count once towards support: several of them converging to one basin is no independent evidence; the
turns of the last pose (:mod:`.recovery`) likewise.
"""
from __future__ import annotations

import enum
from typing import Optional

import numpy as np

from cemnet_ros.core.geometry import turned_in_place
from cemnet_ros.pipeline.steps.health import disagreement
from cemnet_ros.pipeline.steps.polish import Polisher
from cemnet_ros.pipeline.steps.verdict import Estimate, StepJudge

DISTINCT_M, DISTINCT_RAD = 0.1, np.radians(1.0)  # answers farther apart than what the node vouches for differ


class Origin(str, enum.Enum):
    """The kind of start an answer was polished from."""

    PREDICTION = "prediction"  # the motion model's pose
    CEM = "cem"  # the tracking CEM's answer around the prediction
    LAST_POSE = "last pose"  # the sensor did not move as it did (a stop, a jerk, a turn reversed)
    SEARCH = "search"  # a hypothesis of the global search
    TURN = "turn"  # the last pose turned by a few tens of degrees (the recovery's grid of turns)
    NEIGHBOUR = "neighbour"  # an answer turned by the fine polish's reach either way (its basin checked)


def distinct(T_a: np.ndarray, T_b: np.ndarray) -> bool:
    """Two answers that differ by more than the precision the node vouches for."""
    metres, radians = disagreement(T_a, T_b)
    return metres > DISTINCT_M or radians > DISTINCT_RAD


class Contest:
    """The answers of one scan against one map, around the prediction ``T_predicted``.

    ``near`` (metres, radians): how far from the prediction an answer may lie and still be the prediction's (a
    few tracking spreads). ``prediction_std`` (m): its square is the variance kept along unconstrained directions.
    """

    def __init__(self, polisher: Polisher, judge: StepJudge, T_predicted: np.ndarray, near: tuple[float, float],
                 prediction_std: float, recovered: bool = False) -> None:
        self.polisher, self.judge, self.T_predicted = polisher, judge, T_predicted
        self.near, self.prediction_std, self.recovered = near, prediction_std, recovered
        self.answers: list[Estimate] = []
        self._arrivals: list[tuple[Origin, np.ndarray]] = []  # every start's landing place, polished or not
        self._entered: list[tuple[np.ndarray, bool]] = []  # (start, wide) already polished
        self.polishes = 0  # fine polishes run (the contest's cost, reported per scan)

    def recentred(self, T_predicted: np.ndarray) -> "Contest":
        """An empty contest on the same terms around another guess (the prediction left the map)."""
        return Contest(self.polisher, self.judge, T_predicted, self.near, self.prediction_std, self.recovered)

    def escalate(self, prediction_std: float) -> None:
        """From now on the answers are the global search's (judged as recovered, with its wider variance)."""
        self.recovered, self.prediction_std = True, prediction_std

    def enter(self, T_start: np.ndarray, origin: Origin, *, wide: bool = False, spread_m: float = 0.0
              ) -> Optional[Estimate]:
        """Polish ``T_start`` (wide: the basin first) and judge it; the answer, or None when this start was
        entered already or its basin is an answer already there (which gains ``origin``'s support).
        ``spread_m``: the CEM's final spread, a recorded signal."""
        if any(w == wide and not distinct(T_start, T) for T, w in self._entered):
            return None
        self._entered.append((T_start, wide))
        T_polish_start = T_start
        if wide:
            T_polish_start = self.polisher.basin(T_start)
            if any(not distinct(T_polish_start, a.T_odom_sensor) for a in self.answers):
                self._arrivals.append((origin, T_polish_start))
                return None
        polish = self.polisher.fine(T_polish_start)
        self.polishes += 1
        answer = self.judge.judge(self.polisher.frame, self.polisher.map, self.T_predicted, T_start, polish,
                                  spread_m, recovered=self.recovered, prediction_std=self.prediction_std,
                                  origin=origin.value)
        answer.explained = self.polisher.within_reach(polish, self.T_predicted)
        self.answers.append(answer)
        self._arrivals.append((origin, answer.T_odom_sensor))
        return answer

    def support(self, answer: Estimate) -> int:
        """The kinds of start that reached ``answer``."""
        return len({origin for origin, T in self._arrivals if not distinct(T, answer.T_odom_sensor)})

    def standing(self) -> Optional[Estimate]:
        """The most consistent answer that stands (see the module), or None."""
        level = self.judge.health.level
        for answer in self.ranked():
            if answer.failures or level is None or self.judge.health.unconfirmed(answer.signals.fitness, 1):
                continue
            support = self.support(answer)
            evidence = support >= 2 or self.judge.health.covers(answer.signals.coverage)
            if answer.explained or (evidence and self._near(answer)):
                answer.support = support
                return answer
        return None

    def choose(self, tie_ratio: float) -> Estimate:
        """The most consistent answer, or among distinct near-ties the one nearest the prediction (see the
        module)."""
        ranked = self.ranked()
        for answer in ranked:
            answer.support = self.support(answer)
        best = ranked[0]
        ties = [best]
        margin = (1.0 - tie_ratio) * best.signals.fitness  # on a scan the map covers: within tie_ratio in fitness
        for answer in ranked[1:]:
            if answer.signals.consistency >= best.signals.consistency - margin and all(
                    distinct(answer.T_odom_sensor, kept.T_odom_sensor) for kept in ties):
                ties.append(answer)
        if len(ties) == 1:
            return best
        nearest = min(ties, key=lambda a: a.offset_from(self.T_predicted)[0])
        summary = f"{len(ties)} distinct answers within {margin:.3f} of the best consistency"
        if self._near(nearest):
            nearest.notes.append(f"symmetric scene: {summary}, the one next to the motion prediction kept")
            nearest.tied = True
            return nearest
        best.failures.append(f"ambiguous: {summary}, none next to the motion prediction")
        return best

    def checked_against_neighbours(self, answer: Estimate, tie_ratio: float) -> Estimate:
        """``answer``, or the neighbour that replaces it, after the neighbour check (see the module) when it is
        accepted on a weakly constrained view; a near-tie in consistency (within ``1 - tie_ratio`` of its
        fitness) flags it as a symmetric scene does."""
        if not answer.accepted or answer.signals.conditioning >= self.judge.health.config.neighbour_conditioning:
            return answer
        for sign in (1.0, -1.0):
            self.enter(turned_in_place(answer.T_odom_sensor, np.array([sign * self.polisher.reach_rad, 0.0, 0.0])),
                       Origin.NEIGHBOUR)
        rivals = [a for a in self.answers if a.origin == Origin.NEIGHBOUR.value and not a.failures
                  and distinct(a.T_odom_sensor, answer.T_odom_sensor)]
        if not rivals:
            return answer
        best = max(rivals, key=lambda a: a.signals.consistency)
        margin = (1.0 - tie_ratio) * answer.signals.fitness
        if best.signals.consistency > answer.signals.consistency + margin:
            best.support = self.support(best)
            return best
        if best.signals.consistency >= answer.signals.consistency - margin:
            metres, radians = disagreement(answer.T_odom_sensor, best.T_odom_sensor)
            answer.notes.append(f"a neighbour {metres:.2f} m / {np.degrees(radians):.1f} deg away fits as well")
            answer.tied = True
        return answer

    def ranked(self) -> list[Estimate]:
        """The answers, most consistent first."""
        return sorted(self.answers, key=lambda a: -a.signals.consistency)

    def _near(self, answer: Estimate) -> bool:
        """Within ``near`` of the prediction along the directions the scene constrains."""
        metres, radians = answer.offset_from(self.T_predicted)
        return metres <= self.near[0] and radians <= self.near[1]
