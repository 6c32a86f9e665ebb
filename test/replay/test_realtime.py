"""The node's queue played on a virtual clock: drops, backlogs and latencies as the node's worker would see them."""
from __future__ import annotations

import pytest

from cemnet_ros.replay import realtime
from cemnet_ros.replay.realtime import live_summary, play_live


class FakeClock:
    """perf_counter for the play: each handled item advances it by its cost (s)."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def clock(monkeypatch):
    fake = FakeClock()
    monkeypatch.setattr(realtime.time, "perf_counter", fake)
    return fake


def play(clock, costs, rate=1.0, queue_size=2, period_ns=100_000_000):
    seen = []

    def handle(k, backlog, period_s):
        seen.append((k, backlog))
        clock.now += costs[k]

    scans = play_live(range(len(costs)), lambda k: k * period_ns, rate, queue_size, handle)
    return scans, seen


def test_a_node_faster_than_its_input_processes_every_scan_at_once(clock):
    scans, seen = play(clock, [0.05] * 5)
    assert seen == [(k, 0) for k in range(5)]
    assert [s.latency_s for s in scans] == pytest.approx([0.05] * 5)


def test_a_slow_scan_makes_the_next_ones_wait_and_start_behind(clock):
    scans, seen = play(clock, [0.25, 0.03, 0.03, 0.03, 0.03])
    # scan 0 runs 0-0.25 s; 1 and 2 arrive meanwhile and wait: 1 starts behind 2, which catches up
    assert seen == [(0, 0), (1, 1), (2, 0), (3, 0), (4, 0)]
    assert scans[1].start_s == pytest.approx(0.25) and scans[1].latency_s == pytest.approx(0.18)
    assert scans[2].start_s == pytest.approx(0.28) and scans[3].start_s == pytest.approx(0.31)


def test_a_full_queue_drops_its_oldest_waiting_scan(clock):
    scans, seen = play(clock, [0.45, 0.01, 0.01, 0.01, 0.01, 0.01])
    # while scan 0 runs (0-0.45 s) scans 1-4 arrive into a queue of 2: 1 and 2 are dropped
    assert [k for k, _ in seen] == [0, 3, 4, 5] and [s.dropped for s in scans] == [False, True, True] + [False] * 3
    summary = live_summary(scans)
    assert (summary["processed"], summary["dropped"], summary["behind"]) == (4, 2, 1)


def test_a_faster_rate_compresses_the_arrivals(clock):
    _, seen = play(clock, [0.08] * 4, rate=2.0)  # 50 ms apart at 2x, 80 ms a scan: the queue grows
    assert [b for _, b in seen] == [0, 0, 1, 0]  # scan 2 starts at 0.16 s with scan 3 (0.15 s) waiting


def test_bad_rates_and_queues_are_refused():
    with pytest.raises(ValueError):
        play_live([], int, 0.0, 2, lambda item, backlog, period_s: None)
    with pytest.raises(ValueError):
        play_live([], int, 1.0, 0, lambda item, backlog, period_s: None)
