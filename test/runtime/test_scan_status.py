"""Each input's ~/scan_status verdict and log lines without DDS: levels, counters, throttling, first tracebacks."""
from __future__ import annotations

from types import SimpleNamespace

from cemnet_ros.runtime.node_status import ERROR, OK, WARN, NodeStatus
from cemnet_ros.runtime.scan_status import ScanStatus


class Clock:
    def __init__(self):
        self.now = 50.0

    def __call__(self):
        return self.now


def _scan_status():
    clock = Clock()
    return ScanStatus(NodeStatus(1.0, clock=clock), period_s=5.0, clock=clock), clock


def _step(accepted=True, warnings=(), map_restarted=False):
    return SimpleNamespace(stamp_ns=2_500_000_000, accepted=accepted, reason="" if accepted else "low fitness",
                           fitness=0.812345, recovered=False, warnings=list(warnings), recovery_reason="",
                           degenerate=False, origin="prediction" if accepted else "", effort=0.5, polishes=2,
                           map_restarted=map_restarted)


def test_warnings_are_throttled_per_kind_not_per_call_site():
    scan_status, clock = _scan_status()
    assert scan_status.throttled("cdr", "a") == ["a"]
    assert scan_status.throttled("cdr", "b") == []  # the same kind within the period
    assert scan_status.throttled("stamp", "c") == ["c"]  # another kind is not hidden behind the first
    clock.now += 5.0
    assert scan_status.throttled("cdr", "d") == ["d"]


def test_a_rejected_input_is_an_error_verdict_counted_by_kind():
    scan_status, _ = _scan_status()
    first = scan_status.rejected("stamp", "stamp 60 s ahead", 123)
    second = scan_status.rejected("stamp", "stamp 61 s ahead", 124)
    assert (first.verdict.level, first.verdict.stamp_ns, first.verdict.values) == (ERROR, 123, {"rejected": "stamp"})
    assert first.warnings == ["[stamp] stamp 60 s ahead (1 rejected so far)"] and second.warnings == []
    assert second.verdict.message == "stamp 61 s ahead" and scan_status.status.rejected["stamp"] == 2


def test_an_unpaired_source_names_its_stamp_and_the_tolerance():
    scan_status, _ = _scan_status()
    outcome = scan_status.unpaired(3_250_000_000, 50_000_000)
    assert outcome.verdict.message == "source at 3.250 s has no target within 0.050 s"
    assert outcome.verdict.values == {"rejected": "unpaired"} and scan_status.status.rejected["unpaired"] == 1


def test_steps_are_ok_or_flagged_and_carry_their_input_warnings():
    scan_status, _ = _scan_status()
    good = scan_status.step(_step(warnings=[("decimated", "kept 1 in 2")]))
    assert (good.verdict.level, good.verdict.message, good.verdict.stamp_ns) == (OK, "ok", 2_500_000_000)
    assert good.verdict.values == {"fitness": 0.8123, "recovered": False, "origin": "prediction", "effort": 0.5,
                                   "polishes": 2, "map_restarted": False, "warnings": "[decimated] kept 1 in 2"}
    assert good.warnings == ["[decimated] kept 1 in 2 (1 so far)"]
    flagged = scan_status.step(_step(accepted=False, map_restarted=True))
    assert (flagged.verdict.level, flagged.verdict.message) == (WARN, "low fitness")
    assert flagged.verdict.values["map_restarted"] is True  # a consumer sees where the odometry's map began again
    assert flagged.warnings == ["step at 2.500 s flagged: low fitness"]
    counts = scan_status.status
    assert counts.published == 2 and counts.flagged == 1 and counts.warned["decimated"] == 1


def test_the_first_error_of_each_type_comes_with_its_traceback():
    scan_status, _ = _scan_status()

    def raised(exc):
        try:
            raise exc
        except Exception as caught:  # noqa: BLE001 - a traceback to format
            return caught

    first = scan_status.error(raised(IndexError("lattice")), 7)
    again = scan_status.error(raised(IndexError("lattice")), 8)
    other = scan_status.error(raised(KeyError("x")), None)
    assert first.error.startswith("registration failed: IndexError: lattice\nTraceback") and again.error is None
    assert other.error is not None and other.verdict.stamp_ns is None
    assert (first.verdict.level, first.verdict.values) == (ERROR, {"error": "IndexError"})
    assert first.warnings and not again.warnings  # the error warning is throttled like any other


def test_a_flagged_step_confirmed_later_gets_a_second_verdict_ok_and_is_counted():
    scan_status, _ = _scan_status()
    scan_status.step(_step(accepted=False))
    late = scan_status.vouched_late(2_500_000_000)
    assert (late.verdict.level, late.verdict.stamp_ns, late.verdict.values) == (OK, 2_500_000_000,
                                                                              {"vouched_late": True})
    assert late.warnings == [] and scan_status.status.vouched_late == 1 and scan_status.status.flagged == 1
