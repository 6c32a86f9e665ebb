"""ScanAligner on a synthetic street scene with the real engine: tracking, recovery, flags, pair mode."""
from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest
from street_scene import make_transform, make_world, street_scan

from benchmarks.metrics import relative_error, within
from cemnet_ros.pipeline.aligner import ScanAligner
from cemnet_ros.pipeline.config import AlignerConfig, InputChecksConfig, PreprocessConfig, TrackingConfig
from cemnet_ros.pipeline.errors import ScanRejected
from cemnet_ros.pipeline.steps.covariance import moved_by
from cemnet_ros.pipeline.steps.decision import Outcome, Verdict
from cemnet_ros.pipeline.steps.preprocess import robust_radius
from cemnet_ros.pipeline.steps.registration import Registration
from cemnet_ros.pipeline.steps.starts import Starts

DEFAULT = AlignerConfig()  # the node's defaults (the tracking CEM preset)
WORLD = make_world()
PERIOD = 100_000_000


def drive(aligner, poses, seed=2, stamps=None):
    rng = np.random.default_rng(seed)
    stamps = stamps if stamps is not None else [k * PERIOD for k in range(len(poses))]
    return [aligner.process(street_scan(WORLD, p, rng), s) for p, s in zip(poses, stamps)]


def step_error(poses, steps, k, j=None):
    j = k - 1 if j is None else j
    return relative_error(np.linalg.inv(steps[j].pose) @ steps[k].pose, np.linalg.inv(poses[j]) @ poses[k])


def test_first_scan_starts_the_map_and_the_first_pair_runs_the_global_search():
    aligner = ScanAligner(DEFAULT)
    poses = [np.eye(4), make_transform(yaw=0.03, t=(0.6, 0.1, 0.0))]
    first, second = drive(aligner, poses)
    assert first.accepted and first.relative is None and not first.recovered
    np.testing.assert_array_equal(first.pose, np.eye(4))
    assert len(aligner.local_map) > 0 and aligner.scale == pytest.approx(robust_radius(street_scan(
        WORLD, np.eye(4), np.random.default_rng(2))), rel=0.1)
    assert second.recovered and second.accepted and second.recovery_reason == "first pair", second.reason
    assert within(*step_error(poses, [first, second], 1), 0.02, 0.1)


def test_first_pair_survives_a_large_motion():
    aligner = ScanAligner(DEFAULT)
    poses = [np.eye(4), make_transform(yaw=np.radians(140.0), t=(3.0, -2.0, 0.0))]
    steps = drive(aligner, poses)
    trans, rot = step_error(poses, steps, 1)
    assert steps[1].accepted and trans < 0.05 and rot < 0.2, (trans, rot, steps[1].reason)


def test_sequential_tracking_follows_known_motion_and_the_spread_adapts():
    aligner = ScanAligner(DEFAULT)
    poses = [make_transform(yaw=0.02 * k, t=(0.5 * k, 0.05 * k, 0.0)) for k in range(6)]
    steps = drive(aligner, poses)
    assert all(s.accepted for s in steps), [s.reason for s in steps]
    assert not any(s.recovered for s in steps[2:])  # tracking after the first pair
    for k in range(1, 6):
        trans, rot = step_error(poses, steps, k)
        assert trans < 0.02 and rot < 0.1, (k, trans, rot)
        assert 0.5 < steps[k].fitness <= 1.0
    assert aligner._spread.spread()[1] < DEFAULT.adaptive.initial_translation  # a good prediction narrows it


def sampled_and_searched(monkeypatch, aligner, poses):
    """The steps of ``drive``, and on each whether the tracking CEM sampled and whether the global search ran."""
    calls: list[str] = []

    def counted(owner, name, event):
        original = getattr(owner, name)

        def wrapper(*args, **kwargs):
            calls.append(event)
            return original(*args, **kwargs)

        monkeypatch.setattr(owner, name, wrapper)

    counted(Starts, "cem", "cem")
    counted(Starts, "search", "search")
    counted(aligner, "process", "scan")
    steps = drive(aligner, poses)
    events: list[list[str]] = []
    for call in calls:
        if call == "scan":
            events.append([])
        else:
            events[-1].append(call)
    return steps, [tuple(e) for e in events]


def test_a_steady_drive_is_tracked_by_the_polished_prediction_and_a_jerk_by_the_prediction_from_afar(monkeypatch):
    aligner = ScanAligner(DEFAULT)
    poses = [make_transform(yaw=0.02 * k, t=(0.5 * k, 0.05 * k, 0.0)) for k in range(6)]
    poses.append(poses[-1] @ make_transform(yaw=-0.06, t=(0.1, -0.4, 0.0)))  # the prediction is 0.6 m / 4.6 deg off
    steps, events = sampled_and_searched(monkeypatch, aligner, poses)
    assert all(s.accepted for s in steps), [s.reason for s in steps]
    # a steady drive: the polished prediction stands, one polish a scan
    assert events[3:6] == [()] * 3 and [(s.origin, s.polishes) for s in steps[3:6]] == [("prediction", 1)] * 3
    # the jerk is beyond the fine polish's reach and the prediction's spread: the prediction's wide polish (GICP
    # basin first) lands on the truth, confirmed at the running level, and the CEM never samples
    assert events[6] == () and steps[6].origin == "prediction" and steps[6].polishes >= 1
    for k in range(1, len(poses)):
        assert within(*step_error(poses, steps, k), 0.02, 0.1), k


def test_a_wobbling_turn_beyond_the_fine_reach_stands_on_the_prediction_from_afar_without_the_cem(monkeypatch):
    yaws = np.cumsum([0.0] + [0.12 * (-1) ** (k // 2) for k in range(9)])  # 7 deg turns, reversing every 2nd
    poses = [make_transform(yaw=yaw, t=(0.4 * k, 0.05 * k, 0.0)) for k, yaw in enumerate(yaws)]
    steps, events = sampled_and_searched(monkeypatch, ScanAligner(DEFAULT), poses)
    assert all(s.accepted for s in steps), [s.reason for s in steps]
    # once the wobble is the prediction's usual error, its GICP basin stage lands on an answer covering the scan
    assert events[4:] == [()] * 6 and all(s.origin == "prediction" for s in steps[4:])
    for k in range(1, len(poses)):
        assert within(*step_error(poses, steps, k), 0.02, 0.1), k


def test_without_local_first_the_cem_samples_on_every_tracked_step(monkeypatch):
    config = dataclasses.replace(DEFAULT, tracking=TrackingConfig(local_first=False))
    poses = [make_transform(yaw=0.02 * k, t=(0.5 * k, 0.05 * k, 0.0)) for k in range(6)]
    steps, events = sampled_and_searched(monkeypatch, ScanAligner(config), poses)
    assert all(s.accepted for s in steps) and all(e[:1] == ("cem",) for e in events[2:])
    assert all(s.origin == "cem" for s in steps[2:])


def test_a_step_covariance_is_its_registration_plus_the_previous_pose_error_against_the_map(monkeypatch):
    """The map holds the earlier scans where they were registered: a step's motion errs by this registration's
    error and the previous pose's (moved to the current position); the first step's previous pose is the map."""
    registrations = []
    register = Registration.register

    def recorded(self, *args, **kwargs):
        registered = register(self, *args, **kwargs)
        registrations.append(registered)
        return registered

    monkeypatch.setattr(Registration, "register", recorded)
    poses = [make_transform(yaw=0.02 * k, t=(0.5 * k, 0.05 * k, 0.0)) for k in range(4)]
    steps = drive(ScanAligner(DEFAULT), poses)
    assert all(s.accepted for s in steps), [s.reason for s in steps]
    own = [None] + [r.covariance for r in registrations]  # the first scan starts the map: no registration
    np.testing.assert_allclose(steps[1].covariance, own[1])
    for k in range(2, len(steps)):
        lever = steps[k].pose[:3, 3] - steps[k - 1].pose[:3, 3]
        np.testing.assert_allclose(steps[k].covariance, own[k] + moved_by(own[k - 1], lever), rtol=1e-9)


def test_a_scan_of_another_place_is_flagged_and_the_prediction_published():
    aligner = ScanAligner(DEFAULT)
    poses = [make_transform(t=(0.5 * k, 0.0, 0.0)) for k in range(4)]
    steps = drive(aligner, poses)
    elsewhere = np.random.default_rng(9).uniform(-30, 30, (12000, 3))  # no structure of the map
    flagged = aligner.process(elsewhere, 4 * PERIOD)
    assert not flagged.accepted and "prediction" in flagged.reason and flagged.recovered
    np.testing.assert_allclose(flagged.pose, steps[-1].pose @ steps[-1].relative, atol=1e-6)
    assert np.all(np.diag(flagged.covariance) > 10 * np.diag(steps[-1].covariance))
    back = aligner.process(street_scan(WORLD, make_transform(t=(2.5, 0, 0)), np.random.default_rng(3)), 5 * PERIOD)
    assert back.accepted and back.recovered, back.reason  # the next scan searches globally again
    assert within(*relative_error(back.pose, make_transform(t=(2.5, 0, 0))), 0.03, 0.15)


def test_a_kidnapped_sensor_is_found_again_within_one_scan():
    aligner = ScanAligner(DEFAULT)
    poses = [make_transform(t=(0.5 * k, 0.0, 0.0)) for k in range(4)]
    poses.append(make_transform(yaw=np.radians(70.0), t=(6.0, 4.0, 0.0)))  # teleported
    steps = drive(aligner, poses)
    assert steps[-1].recovered and steps[-1].accepted, steps[-1].reason
    assert within(*step_error(poses, steps, 4), 0.05, 0.2)


def test_a_stop_in_a_stamp_gap_stands_after_the_search_and_so_does_a_jump_beyond_every_start():
    aligner = ScanAligner(DEFAULT)
    poses = [make_transform(t=(0.5 * k, 0.0, 0.0)) for k in range(4)]
    poses.append(make_transform(yaw=np.radians(50.0), t=(4.0, 2.0, 0.0)))  # after a second gap: far from both starts
    gap = 2_000_000_000
    stamps = [0, PERIOD, 2 * PERIOD, 2 * PERIOD + gap, 2 * PERIOD + 2 * gap]
    steps = drive(aligner, poses, stamps=stamps)
    # 0.5 m in 2 s where the motion before predicts 10 m: the last pose's answer is no prediction's, the independent
    # starts must find nothing as consistent first ("no motion" is a hypothesis, not a fact)
    assert steps[3].recovered and steps[3].accepted, steps[3].reason
    assert within(*step_error(poses, steps, 3), 0.03, 0.15)
    assert steps[4].recovered and steps[4].accepted, (steps[4].recovery_reason, steps[4].reason)
    assert within(*step_error(poses, steps, 4), 0.05, 0.2)


STOP_POSES = [make_transform(t=(0.5 * k, 0.0, 0.0)) for k in range(4)] + [make_transform(t=(1.5, 0.0, 0.0))]
STOP_STAMPS = [0, PERIOD, 2 * PERIOD, 2 * PERIOD + 2_000_000_000, 3 * PERIOD + 2_000_000_000]


def live_stop_in_a_gap(aligner, rng, scans):
    """The street driven live with no time for the search (the first pair aside): a stop in a gap leaves the
    fourth scan's answer waiting for the search (offline it stands after it)."""
    return [aligner.process(street_scan(WORLD, STOP_POSES[k], rng), STOP_STAMPS[k], budget_s=1e-6 if k > 1 else None)
            for k in scans]


def wait_for_the_check(aligner, timeout_s=120.0):
    """Until the check beside the worker has ended (the next scan takes it in)."""
    deadline = time.monotonic() + timeout_s
    while not aligner._trajectory._unvouched._side._running[1].done():
        assert time.monotonic() < deadline, "the check beside the worker did not end"
        time.sleep(0.01)


def test_a_live_scan_without_time_for_the_search_is_unconfirmed_joins_the_map_and_is_vouched_for_late():
    aligner, rng = ScanAligner(DEFAULT), np.random.default_rng(2)
    steps = live_stop_in_a_gap(aligner, rng, range(3))
    map_size = len(aligner.local_map)
    steps += live_stop_in_a_gap(aligner, rng, [3])
    assert steps[1].recovered and steps[1].accepted  # the first pair's search: its cost is learnt
    unconfirmed = steps[3]
    assert unconfirmed.outcome == "unconfirmed" and not unconfirmed.accepted and not unconfirmed.recovered
    assert "does not fit the scan's budget" in unconfirmed.reason, unconfirmed.reason
    assert within(*step_error(STOP_POSES, steps, 3), 0.03, 0.15)  # the answer is published (flagged)
    assert len(aligner.local_map) > map_size  # in the map, unvouched, checked beside the worker
    assert aligner._trajectory._unvouched._side.busy
    wait_for_the_check(aligner)
    steps += live_stop_in_a_gap(aligner, rng, [4])
    assert "confirmed by the search beside the worker" in steps[4].reason, steps[4].reason
    assert steps[4].vouched_late == [steps[3].stamp_ns]  # the node vouches for the unconfirmed step now
    assert steps[4].accepted and within(*step_error(STOP_POSES, steps, 4), 0.03, 0.15), steps[4].reason
    aligner.reset(aligner.pose)  # a new first pair: its search runs whatever the budget
    first, second = (aligner.process(street_scan(WORLD, pose, rng), 100 * PERIOD + k * PERIOD, budget_s=1e-6)
                     for k, pose in enumerate(STOP_POSES[:2]))
    assert second.recovered and second.accepted and second.recovery_reason == "first pair", second.reason


def test_a_step_registered_while_the_map_holds_an_unvouched_scan_is_flagged_until_the_check_settles():
    aligner, rng = ScanAligner(DEFAULT), np.random.default_rng(2)
    steps = live_stop_in_a_gap(aligner, rng, range(4))
    aligner._trajectory._unvouched.finished = lambda: None  # the check has not ended yet
    held = live_stop_in_a_gap(aligner, rng, [4])[0]
    assert steps[3].outcome == "unconfirmed" and held.outcome == "unconfirmed" and not held.accepted
    assert "the map holds 1 scans the search has yet to vouch for" in held.reason, held.reason
    assert held.vouched_late == []


@pytest.mark.parametrize("placed_elsewhere", [True, False])
def test_a_check_that_does_not_confirm_takes_the_map_back_to_the_one_last_vouched_for(placed_elsewhere):
    aligner, rng = ScanAligner(DEFAULT), np.random.default_rng(2)
    live_stop_in_a_gap(aligner, rng, range(3))
    vouched_size = len(aligner.local_map)
    live_stop_in_a_gap(aligner, rng, [3])
    wait_for_the_check(aligner)
    scan, checked = aligner._trajectory._unvouched.finished()
    shift = make_transform(t=(0.4, 0.0, 0.0))
    if placed_elsewhere:  # the check's answer stands 0.4 m from the one taken in
        checked = dataclasses.replace(checked, T_odom_sensor=shift @ scan.T_inserted)
    else:
        checked = dataclasses.replace(checked, verdict=Verdict(Outcome.FAILED, "no answer stands"))
    aligner._trajectory._unvouched.finished = lambda: (scan, checked)
    pose_before = aligner.pose
    note, vouched = aligner._trajectory.settle_check()
    assert "the map goes back to the one last vouched for" in note and vouched == [], note
    if placed_elsewhere:  # the scan went in where the check placed it; the pose moved by the same correction;
        # the steps since stood on a map rolled back: the next scan runs the search
        assert "placed the step" in note and len(aligner.local_map) > vouched_size
        np.testing.assert_allclose(aligner.pose, shift @ pose_before, atol=1e-9)
        assert aligner._trajectory.pending_recovery.startswith("the search beside the worker placed")
    else:  # the map the node last vouched for, unchanged; the next scan runs the search
        assert len(aligner.local_map) == vouched_size
        np.testing.assert_array_equal(aligner.pose, pose_before)
        assert aligner._trajectory.pending_recovery.startswith("the search beside the worker did not confirm")


def test_a_car_that_keeps_its_speed_through_a_gap_of_a_second_is_tracked_from_the_prediction():
    config = dataclasses.replace(DEFAULT, recovery=dataclasses.replace(DEFAULT.recovery, radius=3.0))
    aligner = ScanAligner(config)
    poses = [make_transform(t=(-10.0 + k, 0.0, 0.0)) for k in range(4)]  # 10 m/s at 10 Hz
    poses.append(make_transform(t=(8.0, 0.0, 0.0)))  # 1.5 s later: 15 m on
    stamps = [k * PERIOD for k in range(4)] + [18 * PERIOD]
    steps = drive(aligner, poses, stamps=stamps)
    assert not steps[4].recovered and steps[4].accepted, steps[4].reason
    assert within(*step_error(poses, steps, 4), 0.03, 0.15)


def test_a_request_triggers_the_global_search():
    aligner = ScanAligner(DEFAULT)
    drive(aligner, [make_transform(t=(0.5 * k, 0.0, 0.0)) for k in range(3)])
    aligner.request_recovery()
    step = aligner.process(street_scan(WORLD, make_transform(t=(1.5, 0, 0)), np.random.default_rng(4)), 3 * PERIOD)
    assert step.recovered and step.recovery_reason == "requested" and step.accepted


def test_stamp_backwards_is_refused_once_then_restarts_and_duplicate_is_skipped():
    aligner = ScanAligner(DEFAULT)
    poses = [make_transform(t=(0.5 * k, 0.0, 0.0)) for k in range(3)]
    steps = drive(aligner, poses, stamps=[1000 + k * PERIOD for k in range(3)])
    dup = aligner.process(street_scan(WORLD, poses[-1], np.random.default_rng(0)), 1000 + 2 * PERIOD)
    assert not dup.accepted and "duplicate" in dup.reason
    np.testing.assert_array_equal(dup.pose, steps[-1].pose)
    with pytest.raises(ScanRejected, match="went back"):  # out of order, or a new time base: the next one says
        aligner.process(street_scan(WORLD, poses[-1], np.random.default_rng(0)), 500)
    back = aligner.process(street_scan(WORLD, poses[-1], np.random.default_rng(0)), 500 + PERIOD)
    assert not back.accepted and "back" in back.reason and back.relative is None
    np.testing.assert_array_equal(back.pose, steps[-1].pose)


def test_too_few_points_is_rejected_without_touching_the_state():
    aligner = ScanAligner(dataclasses.replace(DEFAULT, checks=InputChecksConfig(min_count_ratio=0.0)))
    drive(aligner, [np.eye(4)])
    size = len(aligner.local_map)
    with pytest.raises(ScanRejected, match="too few points"):
        aligner.process(street_scan(WORLD, np.eye(4), np.random.default_rng(0))[:10], PERIOD)
    with pytest.raises(ScanRejected):
        aligner.process(np.full((100, 3), np.nan), PERIOD)
    assert len(aligner.local_map) == size
    assert aligner.process(street_scan(WORLD, make_transform(t=(0.5, 0, 0)), np.random.default_rng(1)), PERIOD).accepted


def test_a_rejected_first_cloud_does_not_fix_the_scale():
    aligner = ScanAligner(DEFAULT)
    two_spots = np.repeat([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]], 30, axis=0)  # 60 points, 2 voxels
    with pytest.raises(ScanRejected, match="after preprocessing"):
        aligner.process(two_spots, 0)
    assert aligner.scale is None
    steps = drive(aligner, [np.eye(4), make_transform(t=(0.5, 0, 0))])
    assert aligner.scale > 1.0 and steps[1].accepted


def _tiny_start_then(aligner, poses):
    """A first scan of 60 points within millimetres, then the street: the errors of the later steps."""
    crumbs = np.random.default_rng(0).normal(size=(60, 3)) * 1e-3
    assert aligner.process(crumbs, 0).accepted
    rng = np.random.default_rng(2)
    steps = [aligner.process(street_scan(WORLD, p, rng), (k + 1) * PERIOD) for k, p in enumerate(poses)]
    return steps, [step_error(poses, steps, k)[0] for k in range(1, len(poses))]


def test_a_tiny_first_scan_is_replaced_by_the_first_representative_one():
    poses = [make_transform(t=(0.5 * k, 0, 0)) for k in range(4)]
    steps, errors = _tiny_start_then(ScanAligner(DEFAULT), poses)
    assert [kind for kind, _ in steps[0].warnings] == ["implausible_start"]
    assert all(s.accepted for s in steps[1:]) and max(errors) < 0.05


def test_a_lost_trajectory_measures_the_auto_scale_again():
    config = dataclasses.replace(DEFAULT, checks=InputChecksConfig(min_count_ratio=0.0))  # no count check
    aligner = ScanAligner(config)
    poses = [make_transform(t=(0.5 * k, 0, 0)) for k in range(config.recovery.restart_after + 4)]
    steps, errors = _tiny_start_then(aligner, poses)
    assert aligner.scale > 1.0
    assert all(s.accepted for s in steps[-2:]) and max(errors[-2:]) < 0.05


def corridor_points(rng, n=12000, half_length=40.0):
    """Walls at y = +-1.5, floor and ceiling at z = -1.2 / 1.8: nothing varies along x."""
    x = rng.uniform(-half_length, half_length, n)
    side = rng.integers(0, 4, n)
    u = rng.uniform(-1.5, 1.5, n)
    y = np.where(side == 0, 1.5, np.where(side == 1, -1.5, u))
    z = np.where(side == 2, -1.2, np.where(side == 3, 1.8, rng.uniform(-1.2, 1.8, n)))
    return np.c_[x, y, z]


def test_corridor_steps_are_flagged_degenerate_and_their_covariance_grows_along_it():
    aligner = ScanAligner(DEFAULT)
    rng = np.random.default_rng(0)
    steps = [aligner.process(corridor_points(rng), k * PERIOD) for k in range(5)]
    later = steps[2:]
    assert all(s.degenerate and not s.accepted and "degenerate" in s.reason for s in later), [s.reason for s in later]
    for s in later:
        assert s.answer is not None and np.array_equal(s.pose, s.answer)  # where the scan placed it, flagged
        cov = s.covariance
        assert cov[0, 0] > 100 * cov[1, 1], np.diag(cov)


def test_config_validation():
    with pytest.raises(ValueError):
        TrackingConfig(centre="magic")
    with pytest.raises(ValueError):
        PreprocessConfig(sampling="magic")
    with pytest.raises(ValueError):
        PreprocessConfig(min_range=10.0, max_range=5.0)


def test_pair_alignment_recovers_the_relative_pose_from_no_guess():
    rng = np.random.default_rng(3)
    source_pose = make_transform(yaw=1.2, t=(2.0, -1.0, 0.0))
    aligner = ScanAligner(DEFAULT)
    target = street_scan(WORLD, np.eye(4), rng)
    step = aligner.align_pair(street_scan(WORLD, source_pose, rng), target, 0)
    assert step.recovered and step.accepted, step.reason
    assert step.polishes >= 1  # the search's hypotheses were polished: the decision's cost is reported
    assert within(*relative_error(step.pose, source_pose), 0.02, 0.1)
    again = aligner.align_pair(street_scan(WORLD, source_pose, rng), target, PERIOD)
    assert again.accepted and not again.recovered and again.polishes >= 1
    assert within(*relative_error(again.pose, source_pose), 0.02, 0.1)


def test_pair_mode_checks_both_clouds_and_a_refused_one_changes_nothing():
    rng = np.random.default_rng(4)
    source_pose = make_transform(yaw=0.3, t=(1.0, 0.5, 0.0))
    aligner = ScanAligner(DEFAULT)
    target = street_scan(WORLD, np.eye(4), rng)
    t0 = 100 * PERIOD
    first = aligner.align_pair(street_scan(WORLD, source_pose, rng), target, t0, source_frame="lidar",
                               target_frame="map")
    assert first.accepted, first.reason
    refusals = [
        (dict(source=street_scan(WORLD, source_pose, rng)[:60], target=target), "point_count"),
        (dict(source=street_scan(WORLD, source_pose, rng), target=target, source_frame="robot2/lidar"), "frame_id"),
        (dict(source=street_scan(WORLD, source_pose, rng), target=target, stamp_ns=t0 - PERIOD), "stamp_back"),
        (dict(source=street_scan(WORLD, source_pose, rng), target=street_scan(WORLD, np.eye(4), rng),
              target_frame="other_map"), "target_frame_id"),
        (dict(source=street_scan(WORLD, source_pose, rng), target=street_scan(WORLD, np.eye(4), rng)[:50]),
         "target_point_count"),
    ]
    for k, (kwargs, kind) in enumerate(refusals):
        kwargs = {"stamp_ns": t0 + (k + 1) * PERIOD, "source_frame": "lidar", "target_frame": "map", **kwargs}
        with pytest.raises(ScanRejected) as info:
            aligner.align_pair(kwargs.pop("source"), kwargs.pop("target"), kwargs.pop("stamp_ns"), **kwargs)
        assert info.value.kind == kind
    after = aligner.align_pair(street_scan(WORLD, source_pose, rng), target, t0 + 10 * PERIOD, source_frame="lidar",
                               target_frame="map")
    assert after.accepted and not after.recovered, after.reason
    assert within(*relative_error(after.pose, source_pose), 0.02, 0.1)


def test_a_prediction_off_the_map_is_searched_where_the_map_grew_never_an_exception():
    """2 m a scan towards the world's edge, then 5 s without scans while the sensor moved 1 m: the constant
    velocity predicts 10 m further, beyond the map (a short CEM radius: 4 m). That raised in the lattice (an
    empty map sample); the global search now starts where the map last grew."""
    config = dataclasses.replace(DEFAULT, preprocess=dataclasses.replace(DEFAULT.preprocess, cem_radius=0.2),
                                 recovery=dataclasses.replace(DEFAULT.recovery, radius=1.0))
    rng = np.random.default_rng(5)
    aligner = ScanAligner(config)
    first = make_transform(t=(10.0, 0.0, 0.0))
    for k in range(4):
        step = aligner.process(street_scan(WORLD, make_transform(t=(10.0 + 2.0 * k, 0.0, 0.0)), rng), k * PERIOD)
        assert step.accepted, (k, step.reason)
    truth = make_transform(t=(17.0, 0.0, 0.0))
    step = aligner.process(street_scan(WORLD, truth, rng), 3 * PERIOD + 5 * 10 ** 9)
    assert step.recovered and step.accepted, step.reason
    assert within(*relative_error(step.pose, np.linalg.inv(first) @ truth), 0.05, 0.2)


def test_a_replay_gives_the_same_trajectory_every_time_and_with_any_thread_count():
    """No time budget, fixed partial sums, single-threaded GICP: what a scan yields does not depend on the machine's
    speed or load (with a global search, the wide stage and the fine polish on the way)."""
    import numba
    import torch

    poses = [make_transform(yaw=np.radians(12.0 * k), t=(0.6 * k, 0.1 * k, 0.0)) for k in range(5)]
    poses.append(make_transform(yaw=np.radians(80.0), t=(5.0, 3.0, 0.0)))  # a kidnap: the global search runs

    def trajectory():
        return np.array([s.pose for s in drive(ScanAligner(DEFAULT), poses)])

    first = trajectory()
    np.testing.assert_array_equal(trajectory(), first)
    threads = numba.get_num_threads(), torch.get_num_threads()
    try:
        numba.set_num_threads(1)
        torch.set_num_threads(1)
        np.testing.assert_array_equal(trajectory(), first)
    finally:
        numba.set_num_threads(threads[0])
        torch.set_num_threads(threads[1])


def test_a_scan_processed_behind_gets_the_effort_share_of_the_polish_and_search_budgets(monkeypatch):
    from cemnet_ros.pipeline.steps import metric_cem, polish

    budgets = {"polish": [], "search": []}
    original_icp, original_search = polish.point_to_plane_icp, metric_cem.global_search

    def icp(*args, **kwargs):
        budgets["polish"].append(args[4])
        return original_icp(*args, **kwargs)

    def search(*args, **kwargs):
        budgets["search"].append(args[4].n_scatter)
        return original_search(*args, **kwargs)

    monkeypatch.setattr(polish, "point_to_plane_icp", icp)
    monkeypatch.setattr(metric_cem, "global_search", search)
    aligner = ScanAligner(DEFAULT)
    poses = [make_transform(yaw=0.02 * k, t=(0.5 * k, 0.05 * k, 0.0)) for k in range(3)]
    rng = np.random.default_rng(2)
    steps = [aligner.process(street_scan(WORLD, p, rng), k * PERIOD, effort=e) for k, (p, e)
             in enumerate(zip(poses, (1.0, 0.5, 1.0)))]
    assert [s.effort for s in steps] == [1.0, 0.5, 1.0] and all(s.accepted for s in steps)
    full, half = DEFAULT.polish.iters, round(0.5 * DEFAULT.polish.iters)
    assert budgets["search"] == [DEFAULT.recovery.search.n_scatter // 2]  # the first pair ran behind
    assert set(budgets["polish"]) == {full, half}


def test_threads_bounds_the_kernels_of_the_calling_thread_and_leaves_the_trajectory_as_it_is(monkeypatch):
    """``threads: 1`` (a robot's one spare core): numba runs the scan's kernels on one thread, the GICP clouds'
    covariances too, and every pose is the one all cores give (the kernels' sums are chunked, not per thread)."""
    import numba
    import torch

    from cemnet_ros.pipeline import threads
    from cemnet_ros.pipeline.map import gicp_cloud

    poses = [make_transform(yaw=0.02 * k, t=(0.5 * k, 0.05 * k, 0.0)) for k in range(4)]
    seen = []
    original = gicp_cloud.small_gicp.estimate_covariances

    def estimate_covariances(*args, **kwargs):
        seen.append(kwargs["num_threads"])
        return original(*args, **kwargs)

    monkeypatch.setattr(gicp_cloud.small_gicp, "estimate_covariances", estimate_covariances)
    one = drive(ScanAligner(dataclasses.replace(DEFAULT, threads=1)), poses)
    assert numba.get_num_threads() == torch.get_num_threads() == 1 and set(seen) == {1}, seen
    every = drive(ScanAligner(DEFAULT), poses)
    assert numba.get_num_threads() == numba.config.NUMBA_NUM_THREADS
    assert torch.get_num_threads() == threads.TORCH_THREADS
    for a, b in zip(one, every):
        np.testing.assert_array_equal(a.pose, b.pose)
        assert a.accepted == b.accepted
