"""Registering a frame: tracking first, the global search when tracking doubts its answer or the caller says why."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from cemnet_ros.pipeline.steps.track_then_recover import RecoveryFallbacks, TrackThenRecover


class FakeContest:
    """Records the neighbour check, which passes every answer through."""

    def __init__(self, name):
        self.name, self.checked = name, []

    def checked_against_neighbours(self, answer, tie_ratio):
        self.checked.append((answer.name, tie_ratio))
        return answer


class FakeTracker:
    def __init__(self, doubts):
        self._doubts, self.calls = doubts, []
        self.config = SimpleNamespace(tracking=SimpleNamespace(tie_ratio=0.9))

    def contest(self, frame, target_map, T_predicted, dt_ratio=1.0, effort=1.0):
        self.calls.append(("contest", dt_ratio, effort))
        return FakeContest("empty contest")

    def track(self, frame, target_map, T_predicted, dt_ratio, T_last, effort=1.0):
        self.calls.append(("track", dt_ratio, T_last, effort))
        return SimpleNamespace(name="tracked"), FakeContest("tracking's contest")

    def doubts(self, estimate, after_gap=False):
        self.calls.append(("doubts", after_gap))
        return list(self._doubts)


class FakeRecovery:
    def __init__(self):
        self.calls = []

    def recover(self, frame, target_map, contest, T_fallback=None, T_last=None):
        self.calls.append((contest.name, T_fallback, T_last))
        return SimpleNamespace(name="recovered")


def _register(doubts, **kwargs):
    tracker, recovery = FakeTracker(doubts), FakeRecovery()
    registered = TrackThenRecover(tracker, recovery).register("frame", "map", np.eye(4), **kwargs)
    return registered, tracker.calls, recovery.calls


def test_an_answer_without_doubts_stands_without_the_search():
    registered, tracked, recovered = _register([], T_last="last", dt_ratio=2.0, effort=0.5, after_gap=True)
    assert (registered.estimate.name, registered.contest.name, registered.why_recovered) == (
        "tracked", "tracking's contest", "")
    assert tracked == [("track", 2.0, "last", 0.5), ("doubts", True)] and recovered == []
    assert registered.contest.checked == [("tracked", 0.9)]  # the answer met the neighbour check


def test_doubts_make_the_search_compete_in_trackings_contest():
    fallbacks = RecoveryFallbacks(T_fallback="map grew here", T_last="last pose")
    registered, _, recovered = _register(["fitness 0.1 < 0.3", "unconfirmed"], fallbacks=fallbacks)
    assert registered.estimate.name == "recovered" and registered.contest.name == "tracking's contest"
    assert registered.why_recovered == "tracking failed (fitness 0.1 < 0.3; unconfirmed)"
    assert recovered == [("tracking's contest", "map grew here", "last pose")]
    assert registered.contest.checked == [("recovered", 0.9)]  # the recovery's answer, not tracking's


def test_a_reason_given_runs_the_search_without_tracking():
    registered, tracked, recovered = _register(["never asked"], recover_because="requested", dt_ratio=3.0)
    assert (registered.estimate.name, registered.why_recovered) == ("recovered", "requested")
    assert tracked == [("contest", 3.0, 1.0)] and recovered == [("empty contest", None, None)]
