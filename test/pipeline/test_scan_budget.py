"""ScanBudget and StageCosts: a long stage runs only where what it has cost fits what is left."""
from __future__ import annotations

import time

import pytest

from cemnet_ros.pipeline.steps.scan_budget import MEMORY, ScanBudget, StageCosts


def test_a_stage_never_run_fits_and_the_turns_are_expected_to_cost_what_the_search_did():
    costs = StageCosts()
    budget = ScanBudget(time.perf_counter(), 0.0, costs)
    assert costs.expected("search") is None and budget.fits("search")  # its cost is learnt by running it
    costs.record("search", 0.4)
    assert costs.expected("turns") == pytest.approx(0.4) and not budget.fits("turns")


def test_the_expected_cost_follows_the_machine_and_decides_what_fits():
    costs = StageCosts()
    costs.record("search", 0.4)
    costs.record("search", 0.2)
    assert costs.expected("search") == pytest.approx(MEMORY * 0.2 + (1.0 - MEMORY) * 0.4)
    started = time.perf_counter()
    assert ScanBudget(started, 10.0, costs).fits("search")
    short = ScanBudget(started, 0.05, costs)
    assert not short.fits("search") and "does not fit the scan's budget" in short.shortfall("search")
