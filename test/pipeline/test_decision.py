"""The decision's rules (cemnet_ros.pipeline.steps.decision) and the evidence record they read, on hand-made answers."""
from __future__ import annotations

import numpy as np
import pytest
from street_scene import make_transform

from cemnet_ros.pipeline.config import HealthConfig
from cemnet_ros.pipeline.steps.answer import Answer, Origin
from cemnet_ros.pipeline.steps.covariance import Conditioning
from cemnet_ros.pipeline.steps.decision import Needs, Outcome, decide
from cemnet_ros.pipeline.steps.evidence import Evidence, Expectation
from cemnet_ros.pipeline.steps.health import Level, Signals

RULES = HealthConfig()
LEVEL = 0.6
COVERAGE = 0.95  # the running coverage of the vouched steps
NEAR = (0.5, 0.1)  # m, rad


def at(x: float, yaw_deg: float = 0.0) -> np.ndarray:
    return make_transform(yaw=np.radians(yaw_deg), t=(x, 0.0, 0.0))


def answer(x: float = 0.0, fitness: float = LEVEL, coverage: float = 1.0, conditioning: float = 0.1,
           explained: bool = False, pairs: int = 500, yaw_deg: float = 0.0, origin: Origin = Origin.SEARCH) -> Answer:
    values = np.array([conditioning, 0.5, 0.6, 0.7, 0.8, 1.0])
    return Answer(at(x, yaw_deg), origin, Signals(fitness, 0.0, 0.0, conditioning, 0.0, coverage),
                  Conditioning(values, np.eye(6), 10.0), 1e-4, pairs, explained)


def evidence(*answers: Answer, level=LEVEL, searched=False, neighbours=False, because="", moving=True,
             missing="", seen_through=lambda answer: 0.0, reach=np.inf, reviewed=lambda answer: True,
             review_agrees=lambda answer: True) -> Evidence:
    """``reviewed``: an answer was polished wide from the map's last scan; ``review_agrees``: that polish landed
    on it (it then supports it)."""
    running = None if level is None else Level(level, COVERAGE)
    expectation = Expectation(at(0.0), NEAR, running, because, moving, reach)

    def support(a: Answer) -> frozenset[Origin]:
        return frozenset({a.origin} | ({Origin.LAST_SCAN} if reviewed(a) and review_agrees(a) else set()))

    return Evidence.of(list(answers), expectation, RULES, support=support,
                       seen_through=seen_through, searched=searched, neighbours_checked=neighbours,
                       last_scan_checked=reviewed, missing=missing)


def test_no_answer_or_no_overlap_fails():
    assert decide(evidence(missing="no map points near the guess"), RULES).reason == "no map points near the guess"
    assert decide(evidence(answer(pairs=3)), RULES).outcome == Outcome.FAILED
    assert decide(evidence(answer(fitness=RULES.min_fitness - 0.01), level=None, searched=True),
                  RULES).outcome == Outcome.FAILED
    below = decide(evidence(answer(fitness=RULES.fitness_drop * LEVEL - 0.01), searched=True), RULES)
    assert below.outcome == Outcome.FAILED and "running level" in below.reason


def test_an_answer_confirmed_where_the_prediction_expects_it_stands_without_the_search():
    assert decide(evidence(answer(explained=True)), RULES).outcome == Outcome.ACCEPTED
    assert decide(evidence(answer(x=0.3)), RULES).outcome == Outcome.ACCEPTED  # within the spread


def test_a_confirmed_answer_away_from_the_prediction_waits_for_the_search_and_then_stands():
    far = answer(x=3.0)
    waiting = decide(evidence(far), RULES)
    assert waiting.outcome == Outcome.UNSETTLED and waiting.needs == Needs.SEARCH
    assert decide(evidence(far, searched=True), RULES).outcome == Outcome.ACCEPTED


def test_an_unconfirmed_answer_stands_after_the_search_only_where_the_prediction_expects_it():
    low = RULES.confirm_ratio * LEVEL - 0.02
    assert decide(evidence(answer(fitness=low, explained=True)), RULES).needs == Needs.SEARCH
    assert decide(evidence(answer(fitness=low), searched=True), RULES).outcome == Outcome.ACCEPTED
    away = decide(evidence(answer(x=3.0, fitness=low), searched=True), RULES)
    assert away.outcome == Outcome.FAILED and "3.00 m / 0.0 deg from the motion prediction" in away.reason
    reached = decide(evidence(answer(x=3.0, fitness=low, origin=Origin.PREDICTION), searched=True), RULES)
    assert reached.outcome == Outcome.ACCEPTED  # the prediction's own polish from afar reached it


def test_an_answer_that_covers_less_of_the_scan_than_the_vouched_steps_did_is_unconfirmed():
    # a turn that fits the walls as well as the truth but leaves a part of the scan where the map has nothing
    short = RULES.confirm_ratio * COVERAGE - 0.02
    waiting = decide(evidence(answer(coverage=short, explained=True)), RULES)
    assert waiting.needs == Needs.SEARCH and waiting.reason.startswith(f"unconfirmed: coverage {short:.3f}")
    assert decide(evidence(answer(coverage=short), searched=True), RULES).outcome == Outcome.ACCEPTED  # expected
    away = decide(evidence(answer(x=3.0, coverage=short), searched=True), RULES)
    assert away.outcome == Outcome.FAILED and "coverage" in away.reason
    covered = RULES.confirm_ratio * COVERAGE + 0.02
    assert decide(evidence(answer(coverage=covered, explained=True)), RULES).outcome == Outcome.ACCEPTED


def test_a_reason_given_makes_the_search_compete_first():
    waiting = decide(evidence(answer(explained=True), because="the previous step failed"), RULES)
    assert waiting.outcome == Outcome.UNSETTLED and waiting.reason == "the previous step failed"
    assert decide(evidence(answer(explained=True), because="x", searched=True), RULES).outcome == Outcome.ACCEPTED


def test_without_a_running_level_the_search_decides_and_a_known_motion_must_expect_the_answer():
    assert decide(evidence(answer(), level=None, moving=False), RULES).needs == Needs.SEARCH
    first_pair = decide(evidence(answer(x=3.0), level=None, moving=False, searched=True), RULES)
    assert first_pair.outcome == Outcome.ACCEPTED
    restarted = decide(evidence(answer(x=3.0), level=None, searched=True), RULES)  # "no motion" after 3 m a step
    assert restarted.outcome == Outcome.FAILED and "3.00 m" in restarted.reason
    assert decide(evidence(answer(x=0.2), level=None, searched=True), RULES).outcome == Outcome.ACCEPTED


def test_near_ties_wait_for_the_search_then_keep_the_one_next_to_the_prediction_or_fail_as_ambiguous():
    margin = (1.0 - RULES.tie_ratio) * LEVEL
    near, far = answer(x=0.2, fitness=LEVEL - margin / 2), answer(x=5.0)
    assert decide(evidence(near, far), RULES).needs == Needs.SEARCH
    tie = decide(evidence(near, far, searched=True), RULES)
    assert tie.outcome == Outcome.NEAR_TIE and tie.failed is False and tie.vouched is False
    both_far = decide(evidence(answer(x=4.0, fitness=LEVEL - margin / 2), far, searched=True), RULES)
    assert both_far.outcome == Outcome.AMBIGUOUS and both_far.failed
    clear = decide(evidence(answer(x=0.2, explained=True), answer(x=5.0, fitness=LEVEL - 2 * margin)), RULES)
    assert clear.outcome == Outcome.ACCEPTED


def test_a_direction_the_view_does_not_constrain_makes_the_step_degenerate():
    verdict = decide(evidence(answer(conditioning=RULES.min_conditioning / 2, explained=True)), RULES)
    assert verdict.outcome == Outcome.DEGENERATE and not verdict.failed and not verdict.vouched


def test_a_weakly_constrained_view_waits_for_its_neighbours():
    weak = answer(conditioning=(RULES.min_conditioning + RULES.neighbour_conditioning) / 2, explained=True)
    assert decide(evidence(weak), RULES).needs == Needs.NEIGHBOURS
    assert decide(evidence(weak, neighbours=True), RULES).outcome == Outcome.ACCEPTED


def test_an_answer_beyond_the_polish_reach_of_the_predicted_position_waits_for_its_neighbours():
    slid = answer(x=0.3, explained=True)  # within the prediction's spread, but beyond a 0.2 m reach
    waiting = decide(evidence(slid, reach=0.2), RULES)
    assert waiting.outcome == Outcome.UNSETTLED and waiting.needs == Needs.NEIGHBOURS
    assert "predicted position" in waiting.reason
    assert decide(evidence(slid, reach=0.2, neighbours=True), RULES).outcome == Outcome.ACCEPTED
    assert decide(evidence(slid, reach=0.5), RULES).outcome == Outcome.ACCEPTED  # within reach: no neighbours
    # A first pair predicts no position: nothing to slide from.
    first = decide(evidence(answer(x=3.0), level=None, searched=True, moving=False, reach=0.2), RULES)
    assert first.needs != Needs.NEIGHBOURS
    # Back at the predicted position, a distinct answer about as consistent makes the slide a near-tie.
    back = answer(x=0.0, fitness=LEVEL - 0.01, origin=Origin.NEIGHBOUR)
    tie = decide(evidence(slid, back, reach=0.2, neighbours=True, searched=True), RULES)
    assert tie.outcome == Outcome.NEAR_TIE


def test_the_leader_among_near_ties_is_the_one_nearest_the_prediction_and_its_rival_the_best_other():
    best_far, near = answer(x=4.0, fitness=0.62), answer(x=0.3, fitness=0.61)
    record = evidence(best_far, near, answer(x=9.0, fitness=0.2))
    assert record.leader is near and record.rival is best_far and len(record.tied) == 2
    assert record.margin == pytest.approx(near.consistency - best_far.consistency)
    alone = evidence(answer(x=0.0))
    assert alone.rival is None and alone.margin == np.inf and alone.tied == ()


def test_answers_closer_than_the_vouched_precision_are_one_and_coverage_ranks_them():
    same = evidence(answer(x=0.0, fitness=0.6), answer(x=0.05, fitness=0.59))
    assert same.tied == () and same.rival is None
    covering = answer(x=2.0, fitness=0.55, coverage=1.0)
    record = evidence(answer(x=0.0, fitness=0.6, coverage=0.8), covering)
    assert record.leader is covering  # consistency: 0.55 against 0.6 - 0.2


def test_nearness_is_measured_in_every_direction_even_one_the_view_leaves_free():
    corridor = answer(x=3.0, conditioning=1e-6)
    assert evidence(corridor).offset[0] == pytest.approx(3.0) and not evidence(corridor).near


def test_an_answer_that_contradicts_what_the_map_saw_empty_does_not_compete():
    through = RULES.max_seen_through * LEVEL + 0.01  # more than the share on the map's surfaces allows
    wrong, right = answer(x=0.1, fitness=LEVEL, coverage=1.0, explained=True), answer(x=3.0, fitness=LEVEL,
                                                                                      coverage=0.99)
    record = evidence(wrong, right, searched=True, seen_through=lambda a: through if a is wrong else 0.0)
    assert record.leader is right and record.contradicted == (wrong,) and record.rival is None
    # ranked below the leader, within its near-tie margin: no near-tie and no rival either
    below = answer(x=0.1, fitness=LEVEL, coverage=0.98)
    record = evidence(right, below, searched=True, seen_through=lambda a: through if a is below else 0.0)
    assert record.leader is right and record.contradicted == (below,) and record.tied == () and record.rival is None
    assert decide(record, RULES).outcome == Outcome.ACCEPTED
    # even where the prediction expects it and the level confirms it: what the map saw empty outweighs both
    alone = evidence(answer(explained=True), seen_through=lambda a: through)
    verdict = decide(alone, RULES)
    assert alone.leader is None and verdict.outcome == Outcome.FAILED and "empty space" in verdict.reason
    assert decide(evidence(answer(explained=True), seen_through=lambda a: through / 2), RULES).outcome == \
        Outcome.ACCEPTED


def test_without_a_level_more_of_the_scan_off_the_map_than_on_its_surfaces_fails():
    sparse = answer(fitness=0.3, coverage=0.6)  # consistency -0.1
    verdict = decide(evidence(sparse, level=None, moving=False, searched=True), RULES)
    assert verdict.outcome == Outcome.FAILED and "off the map (0.400)" in verdict.reason


def test_an_answer_that_would_stand_waits_for_the_map_s_last_scan_first_unless_the_prediction_explains_it():
    right = answer(x=0.3)  # within the prediction's spread, not where its polish converged
    waiting = decide(evidence(right, reviewed=lambda a: False), RULES)
    assert waiting.outcome == Outcome.UNSETTLED and waiting.needs == Needs.LAST_SCAN
    explained = answer(explained=True)  # a steady motion: the prediction's own polish converged to it
    assert decide(evidence(explained, reviewed=lambda a: False), RULES).outcome == Outcome.ACCEPTED
    degenerate = answer(x=0.3, conditioning=RULES.min_conditioning / 2)
    assert decide(evidence(degenerate, reviewed=lambda a: False), RULES).needs == Needs.LAST_SCAN
    assert decide(evidence(degenerate), RULES).outcome == Outcome.DEGENERATE
    weak = answer(x=0.3, conditioning=(RULES.min_conditioning + RULES.neighbour_conditioning) / 2)
    assert decide(evidence(weak, reviewed=lambda a: False), RULES).needs == Needs.NEIGHBOURS  # its basin first
    # What the last scan leads to competes: an equal distinct answer makes a near-tie once the search has run.
    elsewhere = answer(x=0.0, yaw_deg=2.0, origin=Origin.LAST_SCAN)
    assert decide(evidence(right, elsewhere, searched=True), RULES).outcome == Outcome.NEAR_TIE


def test_an_answer_the_map_s_last_scan_leads_away_from_is_disputed_a_near_tie_after_the_search():
    right = answer(x=0.3)
    assert decide(evidence(right), RULES).outcome == Outcome.ACCEPTED  # its review landed on it
    waiting = decide(evidence(right, review_agrees=lambda a: False), RULES)
    assert waiting.outcome == Outcome.UNSETTLED and waiting.needs == Needs.SEARCH and "disputed" in waiting.reason
    # A less consistent answer where the review landed does not tie, yet the map and its last scan disagree.
    elsewhere = answer(x=0.0, yaw_deg=4.0, fitness=0.4 * LEVEL, origin=Origin.LAST_SCAN)
    disputed = decide(evidence(right, elsewhere, searched=True, review_agrees=lambda a: a is elsewhere), RULES)
    assert disputed.outcome == Outcome.NEAR_TIE and "disputed" in disputed.reason and not disputed.failed
    degenerate = answer(x=0.3, conditioning=RULES.min_conditioning / 2)  # its weak direction lets a review slide
    assert decide(evidence(degenerate, review_agrees=lambda a: False), RULES).outcome == Outcome.DEGENERATE
    # a first pair's map is its last scan: the two polishes disagreeing there dispute nothing
    first = evidence(right, level=None, moving=False, searched=True, review_agrees=lambda a: False)
    assert decide(first, RULES).outcome == Outcome.ACCEPTED


def test_a_first_pair_answer_that_survives_only_because_better_ones_were_seen_through_fails():
    through = RULES.max_seen_through * LEVEL + 0.01
    vetoed, survivor = answer(x=0.1, fitness=LEVEL, coverage=1.0), answer(x=4.0, fitness=0.5 * LEVEL, coverage=0.95)
    first = evidence(vetoed, survivor, level=None, moving=False, searched=True,
                     seen_through=lambda a: through if a is vetoed else 0.0)
    assert first.leader is survivor and first.outranked
    verdict = decide(first, RULES)
    assert verdict.outcome == Outcome.FAILED and "empty space" in verdict.reason
    # alone (nothing better seen through) it stands on the search's evidence
    assert decide(evidence(survivor, level=None, moving=False, searched=True), RULES).outcome == Outcome.ACCEPTED
