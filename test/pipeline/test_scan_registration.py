"""The plan run until the decision settles (cemnet_ros.pipeline.steps.registration), on a hand-made landscape:
which stages run, in which order, and what the registration publishes."""
from __future__ import annotations

import numpy as np
import pytest
from landscape import Basin, Landscape, at

from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.steps import registration
from cemnet_ros.pipeline.steps.adaptive import AdaptiveSpread
from cemnet_ros.pipeline.steps.answer import Origin
from cemnet_ros.pipeline.steps.decision import Outcome
from cemnet_ros.pipeline.steps.health import Level
from cemnet_ros.pipeline.steps.starts import Starts

CONFIG = AlignerConfig()


@pytest.fixture
def stages(monkeypatch):
    """The stages each registration ran; the CEM answers at ``cem_at`` and the search with ``hypotheses``."""
    record = {"ran": [], "cem_at": at(0.0), "hypotheses": []}

    def stage(name, body):
        def run(self, contest, *args, **kwargs):
            record["ran"].append(name)
            body(self, contest, *args, **kwargs)
        monkeypatch.setattr(Starts, name, run)

    def search(self, contest):
        contest.searched = True
        for T in record["hypotheses"]:
            contest.enter(T, Origin.SEARCH, wide=True)

    for name in ("prediction", "prediction_from_afar", "last_pose", "turns", "neighbours"):
        stage(name, getattr(Starts, name))
    stage("cem", lambda self, contest: contest.enter(record["cem_at"], Origin.CEM, wide=True))
    stage("search", search)
    return record


def register(landscape, level=Level(0.8, 0.9), credible=True, **kwargs):
    spread = AdaptiveSpread(CONFIG.adaptive)
    if credible:
        spread.update(np.eye(4))  # a prediction that was right: polished finely first
    original = registration.Polisher
    registration.Polisher = lambda *args: landscape
    try:
        return registration.Registration(CONFIG, None, spread).register(
            None, None, at(0.0), level=level, T_last=at(0.0), **kwargs)
    finally:
        registration.Polisher = original


def test_a_confirmed_prediction_stands_after_one_polish(stages):
    registered = register(Landscape(Basin(at(0.05), 0.8)))
    assert registered.verdict.outcome == Outcome.ACCEPTED and stages["ran"] == ["prediction"]
    assert registered.polishes == 1 and not registered.searched and registered.why_searched == ""
    np.testing.assert_allclose(registered.T_odom_sensor, at(0.05))


def test_an_answer_the_prediction_does_not_expect_waits_for_the_search(stages):
    stages["cem_at"] = at(1.4)  # the prediction's basin fits poorly; the CEM finds one 1.5 m away
    stages["hypotheses"] = [at(-3.0)]
    registered = register(Landscape(Basin(at(0.05), 0.3), Basin(at(1.5), 0.8), Basin(at(-3.0), 0.5)))
    # 1.5 m off the predicted position, beyond the polish's reach: its rotation there competes last (and fits 0.3).
    assert stages["ran"] == ["prediction", "prediction_from_afar", "cem", "last_pose", "search", "neighbours"]
    assert registered.verdict.outcome == Outcome.ACCEPTED and registered.searched
    assert registered.why_searched.startswith("tracking failed (unconfirmed")
    np.testing.assert_allclose(registered.answer, at(1.5))


def test_a_reason_given_skips_the_fine_polish_and_the_cem_and_runs_the_turns_when_nothing_stands(stages):
    registered = register(Landscape(Basin(at(0.05), 0.3)), search_because="the previous step failed")
    assert stages["ran"] == ["prediction_from_afar", "last_pose", "search", "turns"]
    assert registered.verdict.outcome == Outcome.FAILED and registered.why_searched == "the previous step failed"


def test_a_weak_view_has_its_neighbours_polished_once(stages):
    weak = CONFIG.health.neighbour_conditioning / 2
    tie = register(Landscape(Basin(at(0.0), 0.8), Basin(at(0.0, 1.5), 0.79), conditioning=weak))
    assert stages["ran"][:2] == ["prediction", "neighbours"] and tie.verdict.outcome == Outcome.NEAR_TIE
    assert "search" in stages["ran"]  # a near-tie lets the search compete before it is kept
    stages["ran"].clear()
    better = register(Landscape(Basin(at(0.0), 0.8), Basin(at(0.0, 1.5), 0.95), conditioning=weak))
    assert stages["ran"] == ["prediction", "neighbours"] and better.verdict.outcome == Outcome.ACCEPTED
    np.testing.assert_allclose(better.T_odom_sensor, at(0.0, 1.5))


def test_an_answer_that_slid_from_the_predicted_position_competes_with_its_rotation_there(stages):
    turned = 20.0  # deg: the prediction's rotation is off (a handheld turn), its position is not
    stages["cem_at"] = at(1.5, turned)  # the CEM lands in a slid basin: the right rotation, 1.5 m along
    right, slid = Basin(at(0.0, turned), 0.9), Basin(at(1.5, turned), 0.8)
    registered = register(Landscape(right, slid), credible=False)
    assert stages["ran"][-1] == "neighbours" and registered.verdict.outcome == Outcome.ACCEPTED
    np.testing.assert_allclose(registered.T_odom_sensor, at(0.0, turned))
    assert Origin.NEIGHBOUR in registered.evidence.support
    stages["ran"].clear()
    as_good = register(Landscape(Basin(at(0.0, turned), 0.79), slid), credible=False)
    # The scene cannot tell them apart: flagged (ambiguous: the prediction's rotation is near neither).
    assert not as_good.verdict.vouched and "distinct answers" in as_good.verdict.reason


def test_an_answer_the_map_s_last_scan_leads_away_from_competes_with_where_it_leads(stages):
    # beyond the fine polish's reach of the prediction (not explained); the last scan leads 2 deg away from it,
    # where the map fits too
    right, turned = Basin(at(0.3), 0.8), at(0.3, 2.0)
    tie = register(Landscape(right, Basin(turned, 0.79), last_scan=((right.pose, turned),)))
    assert tie.verdict.outcome == Outcome.NEAR_TIE and "search" in stages["ran"]  # flagged: the scene cannot tell
    assert Origin.LAST_SCAN in {answer.origin for answer in tie.evidence.tied}
    stages["ran"].clear()
    better = register(Landscape(right, Basin(turned, 0.95), last_scan=((right.pose, turned),)))
    assert better.verdict.outcome == Outcome.ACCEPTED
    np.testing.assert_allclose(better.T_odom_sensor, turned)
    stages["ran"].clear()
    agreed = register(Landscape(right))  # the last scan leads back to the answer: no polish of its own
    assert agreed.verdict.outcome == Outcome.ACCEPTED and agreed.polishes == 2  # the prediction's, from afar
    assert Origin.LAST_SCAN in agreed.evidence.support
    stages["ran"].clear()
    steady = register(Landscape(Basin(at(0.05), 0.8)))  # the prediction's own polish converged to it: no review
    assert steady.verdict.outcome == Outcome.ACCEPTED and stages["ran"] == ["prediction"] and steady.polishes == 1
    assert Origin.LAST_SCAN not in steady.evidence.support


def test_no_answer_anywhere_fails_with_the_reason_and_a_wide_covariance(stages, monkeypatch):
    monkeypatch.setattr(Starts, "prediction_from_afar", lambda self, contest: None)
    monkeypatch.setattr(Starts, "last_pose", lambda self, contest: None)
    monkeypatch.setattr(Starts, "turns", lambda self, contest: None)

    def nothing_here(self, contest):
        contest.searched, contest.missing = True, "no map points within 11.5 m of the guess"

    monkeypatch.setattr(Starts, "search", nothing_here)
    monkeypatch.setattr(Starts, "cem", lambda self, contest: None)
    landscape = Landscape()
    landscape.frame.scale = 1.0
    registered = register(landscape, credible=False)
    assert registered.verdict.outcome == Outcome.FAILED and registered.answer is None
    assert registered.verdict.reason == "no map points within 11.5 m of the guess"
    assert np.all(np.diag(registered.covariance)[3:] >= np.pi ** 2 - 1e-9)
