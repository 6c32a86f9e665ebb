"""Scan pipeline: preprocessing, motion model, covariance, worker queue and ScanAligner behaviour."""
from __future__ import annotations

import dataclasses
import threading
import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cemnet_ros.core import CEMConfig, RegistrationConfig
from cemnet_ros.data.street import make_transform, make_world
from cemnet_ros.pipeline.aligner import ScanAligner
from cemnet_ros.pipeline.config import AlignerConfig, PreprocessConfig, TrackingConfig
from cemnet_ros.pipeline.input_checks import InputChecksConfig, ScanRejected
from cemnet_ros.pipeline.motion import ConstantVelocity, se3_power
from cemnet_ros.pipeline.preprocess import (
    crop_range,
    farthest_point_indices,
    finite_points,
    robust_radius,
    subsample,
    voxel_downsample,
)
from cemnet_ros.pipeline.worker import BoundedWorker


def scan_of(world, pose, rng, n=12000):
    """The world seen from ``pose`` (sensor -> world), a random subset of it like a real scan."""
    pts = (world - pose[:3, 3]) @ pose[:3, :3]
    return pts[rng.permutation(len(pts))[:n]]


def pose_error(a, b):
    err = np.linalg.inv(a) @ b
    return float(np.linalg.norm(err[:3, 3])), float(np.degrees(np.linalg.norm(
        Rotation.from_matrix(err[:3, :3]).as_rotvec())))


# -- preprocessing --------------------------------------------------------------------------------------------
def test_finite_and_crop():
    pts = np.array([[1, 0, 0], [np.nan, 0, 0], [5, 0, 0], [0, 20, 0], [0, 0, np.inf]], dtype=float)
    fin = finite_points(pts)
    assert len(fin) == 3
    np.testing.assert_array_equal(crop_range(fin, 2.0, 10.0), [[5, 0, 0]])
    np.testing.assert_array_equal(crop_range(fin, 0.0, 0.0), fin)
    with pytest.raises(ValueError):
        finite_points(np.zeros((3, 2)))


def test_voxel_downsample_takes_centroids():
    pts = np.array([[0.1, 0.1, 0.1], [0.3, 0.3, 0.3], [1.5, 0.2, 0.2], [-0.5, 0.5, 0.5]])
    out = voxel_downsample(pts, 1.0)
    expected = np.array([[-0.5, 0.5, 0.5], [0.2, 0.2, 0.2], [1.5, 0.2, 0.2]])
    np.testing.assert_allclose(out[np.lexsort(out.T[::-1])], expected[np.lexsort(expected.T[::-1])])
    np.testing.assert_array_equal(voxel_downsample(pts, 0.0), pts)


def test_subsample_is_seeded_and_farthest_spreads():
    pts = np.random.default_rng(0).normal(size=(500, 3))
    a, b = subsample(pts, 50, "random", seed=3), subsample(pts, 50, "random", seed=3)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, subsample(pts, 50, "random", seed=4))
    assert len(subsample(pts[:10], 50)) == 10
    # Farthest-point sampling of two tight clusters picks from both at once.
    clusters = np.vstack([np.zeros((100, 3)), np.full((100, 3), 10.0)]) + np.random.default_rng(1).normal(
        scale=0.01, size=(200, 3))
    idx = farthest_point_indices(clusters, 2)
    assert (idx < 100).sum() == 1
    with pytest.raises(ValueError):
        subsample(pts, 10, "bogus")


def test_robust_radius_ignores_outliers():
    pts = np.random.default_rng(0).uniform(-1, 1, (5000, 3)) + 50.0
    clean = robust_radius(pts)
    assert 0.9 < clean < 1.5
    assert robust_radius(np.vstack([pts, np.full((20, 3), 1e6)])) == pytest.approx(clean, rel=0.05)
    with pytest.raises(ValueError):
        robust_radius(np.zeros((0, 3)))


# -- motion model and covariance ----------------------------------------------------------------------------
def test_constant_velocity_repeats_and_rescales_the_last_motion():
    model = ConstantVelocity()
    np.testing.assert_array_equal(model.predict(5), np.eye(4))
    step = make_transform(yaw=0.1, t=(1.0, 0.2, 0.0))
    model.update(np.eye(4), 0)
    np.testing.assert_array_equal(model.predict_relative(100), np.eye(4))
    model.update(step, 100)
    np.testing.assert_allclose(model.predict_relative(200), step, atol=1e-9)
    np.testing.assert_allclose(model.predict(200), step @ step, atol=1e-9)
    np.testing.assert_allclose(model.predict_relative(300), step @ step, atol=1e-9)  # a dropped scan
    half = se3_power(step, 0.5)
    np.testing.assert_allclose(half @ half, step, atol=1e-9)


# -- worker -----------------------------------------------------------------------------------------------------
def test_worker_drops_oldest_counts_and_survives_errors():
    gate, seen = threading.Event(), []

    def handler(item):
        if item == 0:
            gate.wait(5)
        if item == "bad":
            raise RuntimeError("boom")
        seen.append(item)

    errors = []
    worker = BoundedWorker(handler, maxsize=2, on_error=lambda item, exc: errors.append((item, str(exc))))
    try:
        assert worker.submit(0)
        deadline = time.monotonic() + 5
        while worker.stats().depth and time.monotonic() < deadline:  # item 0 is running and blocks
            time.sleep(0.01)
        results = [worker.submit(i) for i in (1, 2, 3, 4)]
        assert results == [True, True, False, False]
        stats = worker.stats()
        assert stats.depth == 2 and stats.drops == 2
        gate.set()
        assert worker.wait_idle(5)
        assert seen == [0, 3, 4]  # 1 and 2, the oldest, were dropped
        worker.submit("bad")
        worker.submit(5)
        assert worker.wait_idle(5)
        stats = worker.stats()
        assert seen[-1] == 5 and stats.errors == 1 and stats.processed == 4 and errors == [("bad", "boom")]
        assert stats.latency_max_s >= stats.latency_mean_s > 0
    finally:
        gate.set()
        assert worker.close()
    assert not worker.submit(6)


# -- ScanAligner on a synthetic scene with the real engine ---------------------------------------------------
FAST = AlignerConfig(registration=RegistrationConfig(cem=CEMConfig(n_candidates=100, n_iters=3, n_fused_iters=0)))
WORLD = make_world()
PERIOD = 100_000_000


def drive(aligner, poses, seed=2, stamps=None):
    rng = np.random.default_rng(seed)
    stamps = stamps if stamps is not None else [k * PERIOD for k in range(len(poses))]
    return [aligner.process(scan_of(WORLD, p, rng), s) for p, s in zip(poses, stamps)]


def relative_error(poses, steps, k, j=None):
    j = k - 1 if j is None else j
    return pose_error(np.linalg.inv(poses[j]) @ poses[k], np.linalg.inv(steps[j].pose) @ steps[k].pose)


def test_first_scan_starts_the_map_and_the_first_pair_runs_the_global_search():
    aligner = ScanAligner(FAST)
    poses = [np.eye(4), make_transform(yaw=0.03, t=(0.6, 0.1, 0.0))]
    first, second = drive(aligner, poses)
    assert first.accepted and first.relative is None and not first.recovered
    np.testing.assert_array_equal(first.pose, np.eye(4))
    assert len(aligner.local_map) > 0 and aligner.scale == pytest.approx(robust_radius(scan_of(
        WORLD, np.eye(4), np.random.default_rng(2))), rel=0.1)
    assert second.recovered and second.accepted and second.recovery_reason == "first pair", second.reason
    assert relative_error(poses, [first, second], 1) < (0.02, 0.1)


def test_first_pair_survives_a_large_motion():
    aligner = ScanAligner(FAST)
    poses = [np.eye(4), make_transform(yaw=np.radians(140.0), t=(3.0, -2.0, 0.0))]
    steps = drive(aligner, poses)
    trans, rot = relative_error(poses, steps, 1)
    assert steps[1].accepted and trans < 0.05 and rot < 0.2, (trans, rot, steps[1].reason)


def test_sequential_tracking_follows_known_motion_and_the_spread_adapts():
    aligner = ScanAligner(FAST)
    poses = [make_transform(yaw=0.02 * k, t=(0.5 * k, 0.05 * k, 0.0)) for k in range(6)]
    steps = drive(aligner, poses)
    assert all(s.accepted for s in steps), [s.reason for s in steps]
    assert not any(s.recovered for s in steps[2:])  # tracking after the first pair
    for k in range(1, 6):
        trans, rot = relative_error(poses, steps, k)
        assert trans < 0.02 and rot < 0.1, (k, trans, rot)
        assert 0.5 < steps[k].fitness <= 1.0
    assert aligner._spread.spread()[1] < FAST.adaptive.initial_translation  # a good prediction narrows it


def test_a_scan_of_another_place_is_flagged_and_the_prediction_published():
    aligner = ScanAligner(FAST)
    poses = [make_transform(t=(0.5 * k, 0.0, 0.0)) for k in range(4)]
    steps = drive(aligner, poses)
    elsewhere = np.random.default_rng(9).uniform(-30, 30, (12000, 3))  # no structure of the map
    flagged = aligner.process(elsewhere, 4 * PERIOD)
    assert not flagged.accepted and "prediction" in flagged.reason and flagged.recovered
    np.testing.assert_allclose(flagged.pose, steps[-1].pose @ steps[-1].relative, atol=1e-6)
    assert np.all(np.diag(flagged.covariance) > 10 * np.diag(steps[-1].covariance))
    back = aligner.process(scan_of(WORLD, make_transform(t=(2.5, 0, 0)), np.random.default_rng(3)), 5 * PERIOD)
    assert back.accepted and back.recovered, back.reason  # the next scan searches globally again
    assert pose_error(make_transform(t=(2.5, 0, 0)), back.pose) < (0.03, 0.15)


def test_a_kidnapped_sensor_is_found_again_within_one_scan():
    aligner = ScanAligner(FAST)
    poses = [make_transform(t=(0.5 * k, 0.0, 0.0)) for k in range(4)]
    poses.append(make_transform(yaw=np.radians(70.0), t=(6.0, 4.0, 0.0)))  # teleported
    steps = drive(aligner, poses)
    assert steps[-1].recovered and steps[-1].accepted, steps[-1].reason
    assert relative_error(poses, steps, 4) < (0.05, 0.2)


def test_stamp_gap_and_request_trigger_the_global_search():
    aligner = ScanAligner(FAST)
    poses = [make_transform(t=(0.5 * k, 0.0, 0.0)) for k in range(5)]
    stamps = [0, PERIOD, 2 * PERIOD, 2 * PERIOD + 2_000_000_000, 2 * PERIOD + 2_100_000_000]
    steps = drive(aligner, poses, stamps=stamps)
    assert steps[3].recovered and "stamp gap" in steps[3].recovery_reason and steps[3].accepted
    assert not steps[4].recovered
    aligner.request_recovery()
    step = aligner.process(scan_of(WORLD, make_transform(t=(2.5, 0, 0)), np.random.default_rng(4)), 3_000_000_000)
    assert step.recovered and step.recovery_reason == "requested" and step.accepted


def test_stamp_backwards_is_refused_once_then_restarts_and_duplicate_is_skipped():
    aligner = ScanAligner(FAST)
    poses = [make_transform(t=(0.5 * k, 0.0, 0.0)) for k in range(3)]
    steps = drive(aligner, poses, stamps=[1000 + k * PERIOD for k in range(3)])
    dup = aligner.process(scan_of(WORLD, poses[-1], np.random.default_rng(0)), 1000 + 2 * PERIOD)
    assert not dup.accepted and "duplicate" in dup.reason
    np.testing.assert_array_equal(dup.pose, steps[-1].pose)
    with pytest.raises(ScanRejected, match="went back"):  # out of order, or a new time base: the next one says
        aligner.process(scan_of(WORLD, poses[-1], np.random.default_rng(0)), 500)
    back = aligner.process(scan_of(WORLD, poses[-1], np.random.default_rng(0)), 500 + PERIOD)
    assert not back.accepted and "back" in back.reason and back.relative is None
    np.testing.assert_array_equal(back.pose, steps[-1].pose)


def test_too_few_points_is_rejected_without_touching_the_state():
    aligner = ScanAligner(dataclasses.replace(FAST, checks=InputChecksConfig(min_count_ratio=0.0)))
    drive(aligner, [np.eye(4)])
    size = len(aligner.local_map)
    with pytest.raises(ScanRejected, match="too few points"):
        aligner.process(scan_of(WORLD, np.eye(4), np.random.default_rng(0))[:10], PERIOD)
    with pytest.raises(ScanRejected):
        aligner.process(np.full((100, 3), np.nan), PERIOD)
    assert len(aligner.local_map) == size
    assert aligner.process(scan_of(WORLD, make_transform(t=(0.5, 0, 0)), np.random.default_rng(1)), PERIOD).accepted


def test_a_rejected_first_cloud_does_not_fix_the_scale():
    aligner = ScanAligner(FAST)
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
    steps = [aligner.process(scan_of(WORLD, p, rng), (k + 1) * PERIOD) for k, p in enumerate(poses)]
    return steps, [relative_error(poses, steps, k)[0] for k in range(1, len(poses))]


def test_a_tiny_first_scan_is_replaced_by_the_first_representative_one():
    poses = [make_transform(t=(0.5 * k, 0, 0)) for k in range(4)]
    steps, errors = _tiny_start_then(ScanAligner(FAST), poses)
    assert [kind for kind, _ in steps[0].warnings] == ["implausible_start"]
    assert all(s.accepted for s in steps[1:]) and max(errors) < 0.05


def test_a_lost_trajectory_measures_the_auto_scale_again():
    config = dataclasses.replace(FAST, checks=InputChecksConfig(min_count_ratio=0.0))  # no count check
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
    aligner = ScanAligner(FAST)
    rng = np.random.default_rng(0)
    steps = [aligner.process(corridor_points(rng), k * PERIOD) for k in range(5)]
    later = steps[2:]
    assert all(s.degenerate and not s.accepted and "degenerate" in s.reason for s in later), [s.reason for s in later]
    for s in later:
        cov = s.covariance
        assert cov[0, 0] > 100 * cov[1, 1], np.diag(cov)


def test_config_validation():
    with pytest.raises(ValueError):
        TrackingConfig(prior="magic")
    with pytest.raises(ValueError):
        PreprocessConfig(sampling="magic")
    with pytest.raises(ValueError):
        PreprocessConfig(min_range=10.0, max_range=5.0)


def test_pair_alignment_recovers_the_relative_pose_from_no_guess():
    rng = np.random.default_rng(3)
    source_pose = make_transform(yaw=1.2, t=(2.0, -1.0, 0.0))
    aligner = ScanAligner(FAST)
    target = scan_of(WORLD, np.eye(4), rng)
    step = aligner.align_pair(scan_of(WORLD, source_pose, rng), target, 0)
    assert step.recovered and step.accepted, step.reason
    assert pose_error(source_pose, step.pose) < (0.02, 0.1)
    again = aligner.align_pair(scan_of(WORLD, source_pose, rng), target, PERIOD)
    assert again.accepted and not again.recovered
    assert pose_error(source_pose, again.pose) < (0.02, 0.1)


def test_pair_mode_checks_both_clouds_and_a_refused_one_changes_nothing():
    rng = np.random.default_rng(4)
    source_pose = make_transform(yaw=0.3, t=(1.0, 0.5, 0.0))
    aligner = ScanAligner(FAST)
    target = scan_of(WORLD, np.eye(4), rng)
    t0 = 100 * PERIOD
    first = aligner.align_pair(scan_of(WORLD, source_pose, rng), target, t0, source_frame="lidar",
                               target_frame="map")
    assert first.accepted, first.reason
    refusals = [
        (dict(source=scan_of(WORLD, source_pose, rng)[:60], target=target), "point_count"),
        (dict(source=scan_of(WORLD, source_pose, rng), target=target, source_frame="robot2/lidar"), "frame_id"),
        (dict(source=scan_of(WORLD, source_pose, rng), target=target, stamp_ns=t0 - PERIOD), "stamp_back"),
        (dict(source=scan_of(WORLD, source_pose, rng), target=scan_of(WORLD, np.eye(4), rng),
              target_frame="other_map"), "target_frame_id"),
        (dict(source=scan_of(WORLD, source_pose, rng), target=scan_of(WORLD, np.eye(4), rng)[:50]),
         "target_point_count"),
    ]
    for k, (kwargs, kind) in enumerate(refusals):
        kwargs = {"stamp_ns": t0 + (k + 1) * PERIOD, "source_frame": "lidar", "target_frame": "map", **kwargs}
        with pytest.raises(ScanRejected) as info:
            aligner.align_pair(kwargs.pop("source"), kwargs.pop("target"), kwargs.pop("stamp_ns"), **kwargs)
        assert info.value.kind == kind
    after = aligner.align_pair(scan_of(WORLD, source_pose, rng), target, t0 + 10 * PERIOD, source_frame="lidar",
                               target_frame="map")
    assert after.accepted and not after.recovered, after.reason
    assert pose_error(source_pose, after.pose) < (0.02, 0.1)


def test_a_prediction_off_the_map_is_searched_where_the_map_grew_never_an_exception():
    """2 m a scan towards the world's edge, then 5 s without scans while the sensor moved 1 m: the constant
    velocity predicts 10 m further, beyond the map (a short CEM radius: 4 m). That raised in the lattice (an
    empty map sample); the global search now starts where the map last grew."""
    config = dataclasses.replace(FAST, preprocess=dataclasses.replace(FAST.preprocess, cem_radius=0.2),
                                 recovery=dataclasses.replace(FAST.recovery, radius=1.0))
    rng = np.random.default_rng(5)
    aligner = ScanAligner(config)
    first = make_transform(t=(10.0, 0.0, 0.0))
    for k in range(4):
        step = aligner.process(scan_of(WORLD, make_transform(t=(10.0 + 2.0 * k, 0.0, 0.0)), rng), k * PERIOD)
        assert step.accepted, (k, step.reason)
    truth = make_transform(t=(17.0, 0.0, 0.0))
    step = aligner.process(scan_of(WORLD, truth, rng), 3 * PERIOD + 5 * 10 ** 9)
    assert step.recovered and step.accepted, step.reason
    assert pose_error(np.linalg.inv(first) @ truth, step.pose) < (0.05, 0.2)
