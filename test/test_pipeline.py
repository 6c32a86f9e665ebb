"""Scan pipeline: preprocessing, motion model, covariance, worker queue and ScanAligner behaviour."""
from __future__ import annotations

import threading
import time
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cemnet_ros.core import CEMConfig, RegistrationConfig
from cemnet_ros.pipeline.aligner import AlignerConfig, ScanAligner, ScanRejected
from cemnet_ros.pipeline.covariance import MIN_STD_ROTATION, covariance_from_sigma
from cemnet_ros.pipeline.motion import ConstantVelocity, se3_power
from cemnet_ros.pipeline.preprocess import (crop_range, farthest_point_indices, finite_points, robust_radius,
                                            subsample, voxel_downsample)
from cemnet_ros.pipeline.refine import PlaneTarget, point_to_plane_icp
from cemnet_ros.pipeline.worker import BoundedWorker
from street_scene import make_transform, make_world


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


def test_covariance_from_sigma_maps_axes_units_floor_and_inflation():
    sigma = np.array([0.01, 0.02, 0.03, 0.1, 0.2, 0.3])  # z y x (rad), tx ty tz (units)
    cov = covariance_from_sigma(sigma, scale=2.0)
    np.testing.assert_allclose(np.diag(cov), [0.04, 0.16, 0.36, 0.03 ** 2, 0.02 ** 2, 0.01 ** 2])
    assert np.count_nonzero(cov - np.diag(np.diag(cov))) == 0
    floored = covariance_from_sigma(np.zeros(6), scale=2.0)
    assert np.all(np.diag(floored) >= MIN_STD_ROTATION ** 2) and np.linalg.matrix_rank(floored) == 6
    np.testing.assert_allclose(covariance_from_sigma(sigma, 2.0, inflate=100.0), cov * 100.0)
    with pytest.raises(ValueError):
        covariance_from_sigma([np.nan] * 6, 1.0)


# -- ICP refinement ---------------------------------------------------------------------------------------------
def test_point_to_plane_icp_removes_a_small_residual_error():
    world = make_world(n=8000)
    truth = make_transform(yaw=0.02, t=(0.3, -0.1, 0.05))
    source = (world - truth[:3, 3]) @ truth[:3, :3]  # world seen from ``truth``: truth maps source -> world
    start = truth @ make_transform(yaw=0.01, t=(0.08, 0.05, -0.03), roll=0.005)
    refined = point_to_plane_icp(source, PlaneTarget(world), start, 1.0, 0.2, 10)
    before, after = pose_error(truth, start), pose_error(truth, refined)
    assert after[0] < 0.005 and after[1] < 0.02 and after[0] < before[0] / 10, (before, after)
    np.testing.assert_array_equal(point_to_plane_icp(source, PlaneTarget(world), start, 1.0, 0.2, 0), start)


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


# -- ScanAligner with a scripted registrar (fast, exact) -----------------------------------------------------
class ScriptedRegistrar:
    """Stands in for the Registrar: returns prior @ offset (units) with a scripted fitness, records inputs."""

    def __init__(self):
        self.offset = make_transform(t=(0.05, 0.0, 0.0))
        self.fitness = 0.9
        self.calls = []

    def register(self, source, target, prior_pose=None, prior_sigma=None):
        self.calls.append(SimpleNamespace(source=source, target=target, prior=prior_pose, sigma=prior_sigma))
        return SimpleNamespace(transform=prior_pose @ self.offset, fitness=self.fitness,
                               sigma=np.full(6, 0.01))


def scripted(**overrides):
    registrar = ScriptedRegistrar()
    config = AlignerConfig(**{"scale": 10.0, "voxel_size": -1.0, "refine_iters": 0, **overrides})
    return ScanAligner(config, registrar=registrar), registrar


CLOUD = np.random.default_rng(5).uniform(-10, 10, (2000, 3))


def test_first_scan_and_unit_conversion():
    aligner, reg = scripted()
    first = aligner.process(CLOUD, 0)
    assert first.accepted and first.relative is None and first.reason == ""
    np.testing.assert_array_equal(first.pose, np.eye(4))
    step = aligner.process(CLOUD, 100)
    call = reg.calls[-1]
    # Clouds arrive centred on the target centroid and divided by the scale (10 m per unit).
    assert np.linalg.norm(call.target.mean(0)) < 1e-9 and np.abs(call.target).max() <= 1.8
    np.testing.assert_allclose(call.sigma, [0.05] * 3 + [0.05] * 3)  # 0.5 m / 10
    # The unit offset (0.05 units along x) is 0.5 m along x in metres.
    np.testing.assert_allclose(step.relative, make_transform(t=(0.5, 0, 0)), atol=1e-9)
    assert step.accepted and step.n_points == 768


def test_auto_scale_makes_unit_sized_clouds():
    aligner, reg = scripted(scale=0.0)
    aligner.process(CLOUD * 5.0, 0)
    aligner.process(CLOUD * 5.0, 100)
    assert aligner.scale == pytest.approx(robust_radius(CLOUD * 5.0), rel=0.05)
    assert 0.5 < robust_radius(reg.calls[-1].target) < 1.2


def test_low_fitness_is_flagged_and_uses_the_prediction():
    aligner, reg = scripted()
    steps = [aligner.process(CLOUD, k * 100) for k in range(3)]
    normal_cov = steps[-1].covariance
    reg.fitness = 0.1
    flagged = aligner.process(CLOUD, 300)
    assert not flagged.accepted and "low fitness" in flagged.reason and "prediction" in flagged.reason
    # Constant velocity predicts the last relative motion; the registration (prediction @ offset) is ignored.
    np.testing.assert_allclose(flagged.relative, steps[-1].relative, atol=1e-9)
    np.testing.assert_allclose(flagged.pose, steps[-1].pose @ steps[-1].relative, atol=1e-9)
    assert np.all(np.diag(flagged.covariance) >= 100 * np.diag(normal_cov) - 1e-15)


def test_jump_is_flagged_and_does_not_corrupt_the_pose():
    aligner, reg = scripted()
    for k in range(3):
        last = aligner.process(CLOUD, k * 100)
    reg.offset = make_transform(yaw=2.0, t=(30.0, 0, 0))
    jump = aligner.process(CLOUD, 300)
    assert not jump.accepted and "jump" in jump.reason
    np.testing.assert_allclose(jump.pose, last.pose @ last.relative, atol=1e-9)


def test_stamp_backwards_restarts_and_duplicate_is_skipped():
    aligner, _ = scripted()
    for k in range(3):
        last = aligner.process(CLOUD, 1000 + k * 100)
    dup = aligner.process(CLOUD, 1200)
    assert not dup.accepted and "duplicate" in dup.reason
    np.testing.assert_array_equal(dup.pose, last.pose)
    back = aligner.process(CLOUD, 500)
    assert not back.accepted and "back" in back.reason and back.relative is None
    np.testing.assert_array_equal(back.pose, last.pose)
    after = aligner.process(CLOUD, 600)
    assert after.accepted
    np.testing.assert_allclose(after.pose, last.pose @ make_transform(t=(0.5, 0, 0)), atol=1e-9)


def test_too_few_points_is_rejected_without_touching_the_state():
    aligner, _ = scripted()
    aligner.process(CLOUD, 0)
    with pytest.raises(ScanRejected, match="too few points"):
        aligner.process(CLOUD[:10], 100)
    with pytest.raises(ScanRejected):
        aligner.process(np.full((100, 3), np.nan), 100)
    assert aligner.process(CLOUD, 200).accepted


def test_config_validation():
    with pytest.raises(ValueError):
        AlignerConfig(prior="magic")
    with pytest.raises(ValueError):
        AlignerConfig(sampling="magic")
    with pytest.raises(ValueError):
        AlignerConfig(min_range=10.0, max_range=5.0)


# -- ScanAligner with the real engine on a synthetic scene ---------------------------------------------------
SMALL_CEM = RegistrationConfig(cem=CEMConfig(n_candidates=300, n_iters=6))


@pytest.mark.parametrize("refine_iters, max_m, max_deg", [(10, 0.02, 0.1), (0, 0.25, 1.0)])
def test_sequential_alignment_recovers_known_motion(refine_iters, max_m, max_deg):
    world, rng = make_world(), np.random.default_rng(2)
    poses = [make_transform(yaw=0.02 * k, t=(0.5 * k, 0.05 * k, 0.0)) for k in range(5)]
    aligner = ScanAligner(AlignerConfig(registration=SMALL_CEM, refine_iters=refine_iters))
    steps = [aligner.process(scan_of(world, p, rng), k * 100_000_000) for k, p in enumerate(poses)]
    assert all(s.accepted for s in steps), [s.reason for s in steps]
    for k in range(1, 5):
        trans_err, rot_err = pose_error(np.linalg.inv(poses[k - 1]) @ poses[k], steps[k].relative)
        assert trans_err < max_m and rot_err < max_deg, (k, trans_err, rot_err)
        assert 0.3 < steps[k].fitness <= 1.0
    trans_err, _ = pose_error(poses[-1], steps[-1].pose)
    assert trans_err < 0.5
    covs = np.array([np.diag(s.covariance) for s in steps[1:]])
    assert np.ptp(covs, axis=0).max() > 0  # the covariance follows the CEM, it is not a constant


def test_pair_alignment_recovers_the_relative_pose():
    world, rng = make_world(), np.random.default_rng(3)
    target_pose, source_pose = np.eye(4), make_transform(yaw=0.03, t=(0.8, -0.3, 0.0))
    aligner = ScanAligner(AlignerConfig(registration=SMALL_CEM, prior="identity", identity_sigma=0.2))
    target = scan_of(world, target_pose, rng)
    step = aligner.align_pair(scan_of(world, source_pose, rng), target, 0)
    trans_err, rot_err = pose_error(source_pose, step.pose)
    assert step.accepted and trans_err < 0.02 and rot_err < 0.1, (trans_err, rot_err, step.reason)
