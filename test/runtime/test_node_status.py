"""Diagnostics values and levels without DDS: input age and rate, new problems, engine loading."""
from __future__ import annotations

from types import SimpleNamespace

from cemnet_ros.runtime.node_status import CLOCK_GRACE_S, ERROR, OK, WARN, NodeStatus
from cemnet_ros.runtime.pairing import PairMatcher


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def stats(drops=0, errors=0):
    return SimpleNamespace(depth=0, drops=drops, processed=3, errors=errors, latency_last_s=0.02,
                           latency_mean_s=0.02, latency_max_s=0.05)


def test_levels_follow_input_age_loading_and_new_problems():
    clock = Clock()
    status = NodeStatus(input_timeout=1.0, clock=clock)
    report = status.report(stats(), None)
    assert report.level == WARN and "loading" in report.message and report.values["input_age_s"] == ""
    status.ready = True
    for _ in range(10):
        status.input_arrived()
        clock.now += 0.1
    report = status.report(stats(), 20.0)
    assert report.level == OK and report.values["input_rate_hz"] > 0 and report.values["engine_ready"]
    clock.now += 1.5
    assert status.report(stats(), 20.0).level == WARN  # past input_timeout
    clock.now += 2.0
    report = status.report(stats(), 20.0)
    assert report.level == ERROR and "no input" in report.message  # past 3 x input_timeout
    status.input_arrived()
    assert status.report(stats(drops=1), 20.0).level == WARN  # a new drop
    assert status.report(stats(drops=1), 20.0).level == OK  # ... reported once
    status.step_done(SimpleNamespace(recovered=True, accepted=False, fitness=0.5, reason="x", recovery_reason="y",
                                     degenerate=False))
    report = status.report(stats(drops=1), 20.0)
    assert report.level == WARN and report.values["flagged_steps"] == 1 and report.values["recoveries"] == 1


def test_pairs_match_by_stamp_and_report_hopeless_sources():
    scan = lambda ns: SimpleNamespace(stamp_ns=ns)  # noqa: E731
    matcher = PairMatcher(tolerance_ns=50, pending_limit=2, target_depth=3)
    assert matcher.add_source(scan(100)) == ([], [])
    ready, unpaired = matcher.add_target(scan(120))
    assert [(s.stamp_ns, t.stamp_ns) for s, t in ready] == [(100, 120)] and not unpaired
    matcher.add_source(scan(300))
    ready, unpaired = matcher.add_target(scan(500))  # 300 can no longer meet a target within 50
    assert not ready and [s.stamp_ns for s in unpaired] == [300]
    latest = PairMatcher(tolerance_ns=0, pending_limit=2, target_depth=1)
    latest.add_target(scan(0))
    assert latest.add_source(scan(10_000))[0][0][1].stamp_ns == 0  # tolerance 0: always the latest target


def test_the_dds_profile_hint_only_when_matched_publishers_never_delivered():
    clock = Clock()
    status = NodeStatus(input_timeout=1.0, clock=clock)
    status.ready = True
    clock.now += 1.5
    report = status.report(stats(), None, publishers=1)
    assert report.level == WARN and "1 publisher(s) are matched" in report.message and "fastdds" in report.message
    status.input_arrived()  # the transport delivers; the input stops later (the sensor paused, a bag ended)
    clock.now += 1.5
    report = status.report(stats(), None, publishers=1)
    assert report.level == WARN and "no input for 1.5 s" in report.message
    assert "matched" not in report.message and "fastdds" not in report.message


def test_scans_without_a_clock_under_sim_time_warn_after_a_grace_period():
    clock = Clock()
    status = NodeStatus(input_timeout=10.0, clock=clock)
    status.ready = True
    assert status.missing_clock(clock_unset=True) is None  # no scan yet: nothing to say
    status.input_arrived()
    clock.now += CLOCK_GRACE_S - 0.5
    assert status.missing_clock(clock_unset=True) is None
    assert status.report(stats(), None, clock_unset=True).level == OK
    clock.now += 1.0
    status.input_arrived()
    assert status.missing_clock(clock_unset=False) is None
    report = status.report(stats(), None, clock_unset=True)
    assert report.level == WARN and report.values["ros_time_unset"] is True
    assert "use_sim_time is true but no /clock has arrived" in report.message and "--clock" in report.message
    assert status.report(stats(), None, clock_unset=False).level == OK


def test_the_hardware_id_names_the_scans_frame_on_the_input_topic():
    status = NodeStatus(input_timeout=1.0, clock=Clock(), input_topic="/robot1/points")
    assert status.report(stats(), None).hardware_id == "/robot1/points"  # no scan yet
    status.scan_frame("velodyne")
    assert status.hardware_id() == "velodyne on /robot1/points"
    assert status.report(stats(), None).hardware_id == "velodyne on /robot1/points"
    status.scan_frame("")
    assert status.hardware_id() == "/robot1/points"
