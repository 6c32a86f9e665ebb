"""The contest's rules (support, standing, near-ties, ambiguity, distinctness) on a hand-made landscape of basins."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from street_scene import make_transform

from cemnet_ros.pipeline.config import HealthConfig
from cemnet_ros.pipeline.steps.contest import Contest, Origin, distinct
from cemnet_ros.pipeline.steps.health import HealthMonitor, Signals, disagreement
from cemnet_ros.pipeline.steps.refine import PolishResult
from cemnet_ros.pipeline.steps.verdict import Estimate

ITERS = 20
REACH = 0.2  # m: the fake fine polish's pairing distance
LENGTH = 10.0  # m: the lever arm that makes a rotation a distance (the fake frame's RMS range)


@dataclass
class Basin:
    pose: np.ndarray
    fitness: float
    coverage: float = 1.0


class Landscape:
    """A fake Polisher: the fine polish settles in the basin within REACH of its start (converged), else stays
    (its budget spent); the basin stage (GICP) finds any basin within 2 m."""

    def __init__(self, *basins: Basin, conditioning: float = 1.0) -> None:
        self.basins, self.conditioning = list(basins), conditioning
        self.frame, self.map, self.effort, self.iters, self.reach = None, None, 1.0, ITERS, REACH
        self.reach_rad = REACH / LENGTH

    def _nearest(self, T: np.ndarray, radius: float):
        def apart(b: Basin) -> float:
            metres, radians = disagreement(b.pose, T)
            return metres + LENGTH * radians

        near = [b for b in self.basins if apart(b) <= radius]
        return min(near, key=apart) if near else None

    def fine(self, T_start: np.ndarray) -> PolishResult:
        basin = self._nearest(T_start, REACH)
        T = T_start if basin is None else basin.pose
        return PolishResult(T.copy(), np.eye(6), 1e-4, 500, ITERS if basin is None else 5)

    def basin(self, T_start: np.ndarray) -> np.ndarray:
        basin = self._nearest(T_start, 2.0)
        return T_start if basin is None else basin.pose.copy()

    def within_reach(self, polish: PolishResult, T_pose: np.ndarray) -> bool:
        return polish.iterations < ITERS and np.linalg.norm(polish.T_target_source[:3, 3] - T_pose[:3, 3]) <= REACH

    def fitness(self, T: np.ndarray) -> float:
        basin = self._nearest(T, 1e-6)
        return 0.1 if basin is None else basin.fitness

    def coverage(self, T: np.ndarray) -> float:
        basin = self._nearest(T, 1e-6)
        return 0.5 if basin is None else basin.coverage


class Judge:
    """A fake StepJudge: fitness from the landscape, the real running level and confirmation."""

    def __init__(self, landscape: Landscape, level: float = 0.8) -> None:
        self.landscape = landscape
        self.health = HealthMonitor(HealthConfig())
        self.health.accept(level)

    def judge(self, frame, target_map, T_predicted, T_start, polish, spread_m, recovered, prediction_std, origin):
        fitness = self.landscape.fitness(polish.T_target_source)
        failures = [] if fitness >= 0.3 else ["low fitness"]
        signals = Signals(fitness, 0.0, 0.0, self.landscape.conditioning, 0.0,
                          coverage=self.landscape.coverage(polish.T_target_source))
        return Estimate(polish.T_target_source, np.eye(6), signals, failures, [],
                        recovered, np.zeros((6, 0)), 10.0, origin)


def at(x: float, yaw_deg: float = 0.0) -> np.ndarray:
    return make_transform(yaw=np.radians(yaw_deg), t=(x, 0.0, 0.0))


def contest(*basins: Basin, near=(0.6, 0.2), conditioning: float = 1.0) -> Contest:
    landscape = Landscape(*basins, conditioning=conditioning)
    return Contest(landscape, Judge(landscape), at(0.0), near, prediction_std=0.1)  # type: ignore[arg-type]


def test_answers_closer_than_the_vouched_precision_are_one():
    assert not distinct(at(0.0), at(0.09)) and not distinct(at(0.0, 0.9), at(0.0))
    assert distinct(at(0.0), at(0.11)) and distinct(at(0.0), at(0.0, 1.1))


def test_a_converged_polish_within_reach_of_the_prediction_stands_alone():
    c = contest(Basin(at(0.1), 0.8))
    answer = c.enter(at(0.0), Origin.PREDICTION)
    assert answer is not None and answer.explained and c.standing() is answer and c.polishes == 1


def test_an_answer_beyond_reach_covering_the_scan_stands_alone_within_the_spread():
    c = contest(Basin(at(0.5), 0.8, coverage=0.99))
    cem = c.enter(at(0.45), Origin.CEM, wide=True)
    assert cem is not None and not cem.explained and c.support(cem) == 1 and c.standing() is cem


def test_an_answer_covering_the_scan_does_not_stand_beyond_the_spread_or_below_the_level():
    far = contest(Basin(at(1.5), 0.8, coverage=0.99))
    far.enter(at(1.4), Origin.CEM, wide=True)
    weak = contest(Basin(at(0.5), 0.6, coverage=0.99))  # below health.confirm_ratio x the level 0.8
    weak.enter(at(0.45), Origin.CEM, wide=True)
    assert far.standing() is None and weak.standing() is None


def test_an_answer_beyond_reach_leaving_part_of_the_scan_off_the_map_needs_a_second_kind_of_start():
    c = contest(Basin(at(0.5), 0.8, coverage=0.9))
    cem = c.enter(at(0.45), Origin.CEM, wide=True)
    assert cem is not None and not cem.explained and c.standing() is None  # one start: it needs a rival
    assert c.enter(at(0.0), Origin.PREDICTION, wide=True) is None  # its basin is the CEM's answer: no new polish
    assert c.support(cem) == 2 and c.standing() is cem and c.polishes == 1


def test_two_starts_agreeing_far_beyond_the_spread_do_not_stand():
    c = contest(Basin(at(1.5), 0.8))
    c.enter(at(1.4), Origin.CEM, wide=True)
    c.enter(at(0.0), Origin.PREDICTION, wide=True)
    assert c.support(c.answers[0]) == 2 and c.standing() is None  # the last pose must compete first


def test_an_unconfirmed_answer_does_not_stand_whatever_its_support():
    c = contest(Basin(at(0.5), 0.6))  # below health.confirm_ratio x the level 0.8
    c.enter(at(0.45), Origin.CEM, wide=True)
    c.enter(at(0.0), Origin.PREDICTION, wide=True)
    assert c.support(c.answers[0]) == 2 and c.standing() is None


def test_the_global_search_counts_once_however_many_hypotheses_reach_an_answer():
    c = contest(Basin(at(1.0), 0.8))
    c.escalate(10.0)
    for x in (0.9, 1.1, 1.2):
        c.enter(at(x), Origin.SEARCH, wide=True)
    assert len(c.answers) == 1 and c.support(c.answers[0]) == 1 and c.answers[0].recovered


def test_a_start_entered_twice_is_polished_once():
    c = contest(Basin(at(0.1), 0.8))
    assert c.enter(at(0.0), Origin.PREDICTION) is not None
    assert c.enter(at(0.05), Origin.PREDICTION) is None and c.polishes == 1
    assert c.enter(at(0.0), Origin.PREDICTION, wide=True) is None  # the wide one lands on the same answer


def test_the_most_consistent_answer_wins_when_no_other_comes_close():
    c = contest(Basin(at(0.1), 0.5), Basin(at(1.5), 0.9))
    c.enter(at(0.0), Origin.PREDICTION)
    c.enter(at(1.4), Origin.LAST_POSE, wide=True)
    chosen = c.choose(0.95)
    assert chosen.origin == "last pose" and not chosen.failures and not chosen.tied


def test_a_fitter_answer_that_leaves_part_of_the_scan_off_the_map_loses_to_one_that_covers_it():
    c = contest(Basin(at(1.5), 0.62, coverage=0.99), Basin(at(-1.5), 0.66, coverage=0.85))
    c.enter(at(1.4), Origin.TURN, wide=True)
    c.enter(at(-1.4), Origin.SEARCH, wide=True)
    chosen = c.choose(0.95)
    assert np.allclose(chosen.T_odom_sensor, at(1.5)) and not chosen.failures and not chosen.tied
    assert c.ranked()[0] is chosen


def test_a_near_tie_in_consistency_is_one_within_the_tie_ratio_of_the_best_fitness():
    c = contest(Basin(at(1.5), 0.80, coverage=0.98), Basin(at(-1.5), 0.80, coverage=0.95))
    c.enter(at(1.4), Origin.CEM, wide=True)
    c.enter(at(-1.4), Origin.LAST_POSE, wide=True)
    assert "ambiguous" in c.choose(0.95).failures[-1]  # 0.03 apart, within 0.05 x 0.80
    c = contest(Basin(at(1.5), 0.80, coverage=0.98), Basin(at(-1.5), 0.80, coverage=0.92))
    c.enter(at(1.4), Origin.CEM, wide=True)
    c.enter(at(-1.4), Origin.LAST_POSE, wide=True)
    chosen = c.choose(0.95)
    assert np.allclose(chosen.T_odom_sensor, at(1.5)) and not chosen.failures  # 0.06 apart: no tie


def test_a_near_tie_keeps_the_answer_next_to_the_prediction_flagged():
    near_x, far_x = 0.3, 1.5
    c = contest(Basin(at(near_x), 0.80), Basin(at(far_x), 0.82))
    c.enter(at(near_x - 0.1), Origin.CEM, wide=True)
    c.enter(at(far_x), Origin.LAST_POSE, wide=True)
    chosen = c.choose(0.95)
    assert np.allclose(chosen.T_odom_sensor, at(near_x)) and chosen.tied and "symmetric scene" in chosen.notes[0]
    assert not chosen.accepted  # flagged: the map does not take it in


def test_near_ties_none_next_to_the_prediction_fail_as_ambiguous():
    c = contest(Basin(at(1.5), 0.80), Basin(at(-1.5), 0.81))
    c.enter(at(1.4), Origin.CEM, wide=True)
    c.enter(at(-1.4), Origin.LAST_POSE, wide=True)
    chosen = c.choose(0.95)
    assert chosen.failures and "ambiguous" in chosen.failures[-1]


def test_an_accepted_answer_on_a_weak_view_is_checked_against_its_rotational_neighbours():
    """Basins 1.5 deg apart in yaw (within two fine reaches, 1.15 deg here): a neighbour about as consistent flags
    the answer, a clearly better one replaces it, a worse one or a well constrained view changes nothing."""
    def checked(neighbour_fitness: float, conditioning: float = 0.01):
        c = contest(Basin(at(0.0), 0.8), Basin(at(0.0, 1.5), neighbour_fitness), conditioning=conditioning)
        answer = c.enter(at(0.0), Origin.PREDICTION)
        assert answer is not None and answer.accepted
        return answer, c.checked_against_neighbours(answer, 0.95), c

    answer, out, c = checked(0.79)
    assert out is answer and out.tied and not out.accepted and "neighbour" in out.notes[0] and c.polishes == 3
    answer, out, _ = checked(0.9)
    assert np.allclose(out.T_odom_sensor, at(0.0, 1.5)) and out.accepted and out.origin == "neighbour"
    answer, out, _ = checked(0.6)
    assert out is answer and out.accepted
    answer, out, c = checked(0.79, conditioning=0.5)  # above health.neighbour_conditioning: not checked
    assert out is answer and out.accepted and c.polishes == 1
