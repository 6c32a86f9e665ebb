"""A live scan's time on the worker: the plan's long stages (the global search, the turns of the last pose) run only
where what they cost on this machine fits what is left of the scan's budget.

A 10 Hz sensor's scan that runs the search holds the worker for 0.3-1.5 s: the scans behind it queue or drop, the
motion between the ones kept grows, and more of them need the search. Within a budget the scan's answer is
published without the search's confirmation instead (flagged *unconfirmed*, :mod:`.decision`), and the next scan
tracks from it. Offline there is no budget: every scan runs its whole plan.
"""
from __future__ import annotations

import time
from typing import Optional

MEMORY = 0.5  # the weight of a stage's last run in its expected cost (a running mean that follows the machine)


def budget_seconds(periods: float, period_s: Optional[float]) -> Optional[float]:
    """``periods`` of ``period_s`` (None: no bound, ``periods`` 0 or no period known yet)."""
    return periods * period_s if periods > 0.0 and period_s is not None else None


class StageCosts:
    """What each long stage has cost on this machine (s): a running mean per stage; a stage not run yet is
    expected to cost what the search does (the turns cost more: the estimate only errs towards running one)."""

    def __init__(self) -> None:
        self._seconds: dict[str, float] = {}

    def expected(self, stage: str) -> Optional[float]:
        """The expected cost of ``stage`` (None: nothing has run yet)."""
        return self._seconds.get(stage, self._seconds.get("search"))

    def record(self, stage: str, seconds: float) -> None:
        last = self._seconds.get(stage)
        self._seconds[stage] = seconds if last is None else MEMORY * seconds + (1.0 - MEMORY) * last


class ScanBudget:
    """The time a scan may hold the worker, from ``started`` (``time.perf_counter()``) for ``seconds``."""

    def __init__(self, started: float, seconds: float, costs: StageCosts) -> None:
        self.deadline, self.costs = started + seconds, costs

    def fits(self, stage: str) -> bool:
        """``stage`` is expected to end before the deadline (one never run is: its cost is learnt by running it)."""
        expected = self.costs.expected(stage)
        return expected is None or time.perf_counter() + expected <= self.deadline

    def shortfall(self, stage: str) -> str:
        """Why ``stage`` did not run, for the step's reason."""
        expected = self.costs.expected(stage) or 0.0
        left = max(0.0, self.deadline - time.perf_counter())
        return f"the {stage} ({expected:.2f} s) does not fit the scan's budget ({left:.2f} s left)"
