"""The contest (cemnet_ros.pipeline.steps.contest): each start polished once, measured, its support kept."""
from __future__ import annotations

import numpy as np
import pytest
from landscape import Basin, Landscape, at

from cemnet_ros.pipeline.steps.answer import Origin, distinct
from cemnet_ros.pipeline.steps.contest import Contest


def contest(*basins: Basin, conditioning: float = 1.0) -> Contest:
    return Contest(Landscape(*basins, conditioning=conditioning), at(0.0))  # type: ignore[arg-type]


def test_answers_closer_than_the_vouched_precision_are_one():
    assert not distinct(at(0.0), at(0.09)) and not distinct(at(0.0, 0.9), at(0.0))
    assert distinct(at(0.0), at(0.11)) and distinct(at(0.0), at(0.0, 1.1))


def test_an_answer_is_measured_once_with_its_overlap_conditioning_and_whether_the_prediction_explains_it():
    c = contest(Basin(at(0.1), 0.8, coverage=0.9), conditioning=0.05)
    answer = c.enter(at(0.0), Origin.PREDICTION)
    assert answer is not None and answer.explained and c.polishes == 1
    assert (answer.fitness, answer.coverage) == (0.8, 0.9) and answer.consistency == pytest.approx(0.7)
    assert answer.signals.conditioning == pytest.approx(0.05) and answer.constrained
    far = c.enter(at(3.0), Origin.LAST_POSE)  # no basin within reach: the polish spends its budget
    assert far is not None and not far.explained


def test_a_start_entered_twice_is_polished_once_and_a_wide_one_landing_on_an_answer_adds_its_support():
    c = contest(Basin(at(0.5), 0.8))
    cem = c.enter(at(0.45), Origin.CEM, wide=True)
    assert cem is not None and c.support(cem) == {Origin.CEM}
    assert c.enter(at(0.46), Origin.CEM, wide=True) is None  # the same start
    assert c.enter(at(0.0), Origin.PREDICTION, wide=True) is None  # its basin is the CEM's answer: no new polish
    assert c.support(cem) == {Origin.CEM, Origin.PREDICTION} and c.polishes == 1


def test_the_global_search_counts_once_however_many_hypotheses_reach_an_answer():
    c = contest(Basin(at(1.0), 0.8))
    for x in (0.9, 1.1, 1.2):
        c.enter(at(x), Origin.SEARCH, wide=True)
    assert len(c.answers) == 1 and c.support(c.answers[0]) == {Origin.SEARCH}


def test_the_evidence_names_the_most_consistent_answer_and_its_rival():
    c = contest(Basin(at(0.1), 0.5), Basin(at(1.5), 0.9))
    c.enter(at(0.0), Origin.PREDICTION)
    c.enter(at(1.4), Origin.LAST_POSE, wide=True)
    record = c.evidence((0.5, 0.1), 0.8, c.polisher.config.health)
    assert record.leader is not None and np.allclose(record.leader.T_odom_sensor, at(1.5))
    assert record.rival is not None and np.allclose(record.rival.T_odom_sensor, at(0.1))
    assert record.support == {Origin.LAST_POSE} and not record.searched and not record.expected


def test_the_prediction_is_recentred_only_before_any_answer():
    c = contest(Basin(at(0.1), 0.5))
    c.recentre(at(5.0))
    assert np.allclose(c.T_predicted, at(5.0))
    c.enter(at(0.0), Origin.SEARCH)
    with pytest.raises(AssertionError):
        c.recentre(at(0.0))


def test_a_review_enters_only_a_distinct_answer_the_map_s_last_scan_leads_to():
    right, aside, elsewhere = at(0.1), at(0.25), at(0.1, 3.0)  # aside: distinct, but within the fine polish's reach
    agreeing = Contest(Landscape(Basin(right, 0.8), last_scan=((right, aside),)), at(0.0))  # type: ignore[arg-type]
    leader = agreeing.enter(at(0.0), Origin.PREDICTION)
    assert leader is not None and not agreeing.reviewed(leader)
    assert agreeing.review(leader) is None and agreeing.reviewed(leader)  # polished back onto the leader
    assert agreeing.polishes == 2 and len(agreeing.answers) == 1 and Origin.LAST_SCAN in agreeing.support(leader)
    disagreeing = Contest(Landscape(Basin(right, 0.8), Basin(elsewhere, 0.8), last_scan=((right, elsewhere),)),  # type: ignore[arg-type]
                          at(0.0))
    leader = disagreeing.enter(at(0.0), Origin.PREDICTION)
    assert leader is not None
    found = disagreeing.review(leader)
    assert found is not None and found.origin == Origin.LAST_SCAN and np.allclose(found.T_odom_sensor, elsewhere)
