"""Tracking's doubts: when its answer cannot stand without the global search competing."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from cemnet_ros.pipeline.config import AlignerConfig, HealthConfig
from cemnet_ros.pipeline.steps.health import HealthMonitor, Signals
from cemnet_ros.pipeline.steps.tracking import Tracker
from cemnet_ros.pipeline.steps.verdict import Estimate


def tracker(level: float = 0.8) -> Tracker:
    health = HealthMonitor(HealthConfig(confirm_ratio=0.9, confirm_coverage=0.95))
    health.accept(level)
    return Tracker(AlignerConfig(), None, None, SimpleNamespace(health=health))  # type: ignore[arg-type]


def answer(fitness: float, coverage: float, support: int = 1, explained: bool = False) -> Estimate:
    signals = Signals(fitness, 0.0, 0.0, 1.0, 0.0, coverage)
    return Estimate(np.eye(4), np.eye(6), signals, [], [], False, np.zeros((6, 0)), 10.0, "cem", support=support,
                    explained=explained)


def test_a_fit_answer_from_one_start_that_leaves_part_of_the_scan_off_the_map_is_doubted():
    doubts = tracker().doubts(answer(0.8, 0.9))
    assert len(doubts) == 1 and "partly off the map" in doubts[0]


def test_support_the_prediction_or_coverage_lift_that_doubt():
    t = tracker()
    assert t.doubts(answer(0.8, 0.9, support=2)) == []
    assert t.doubts(answer(0.8, 0.9, explained=True)) == []
    assert t.doubts(answer(0.8, 0.96)) == []


def test_an_unconfirmed_answer_is_doubted_for_its_fitness_first():
    doubts = tracker().doubts(answer(0.6, 0.9))
    assert len(doubts) == 1 and "unconfirmed" in doubts[0]
    assert tracker().doubts(answer(0.6, 0.96)) == []  # it covers the scan: confirmed
