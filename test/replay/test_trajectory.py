"""Trajectory metrics: ATE after rigid alignment, per-pair RPE, stamp association (TUM files: test/io)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cemnet_ros.replay.trajectory import (
    absolute_trajectory_error,
    associate,
    relative_pose_errors,
)


def _pose(rotvec=(0.0, 0.0, 0.0), t=(0.0, 0.0, 0.0)) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    out[:3, 3] = t
    return out


def _wiggly_path(n: int = 30, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    poses, pose = [], np.eye(4)
    for _ in range(n):
        poses.append(pose.copy())
        pose = pose @ _pose(rng.normal(0, 0.05, 3), rng.normal([0.7, 0, 0], 0.1))
    return np.stack(poses)


def test_ate_of_rigidly_moved_copy_is_zero():
    gt = _wiggly_path()
    moved = np.einsum("ij,njk->nik", _pose((0.3, -1.2, 2.0), (10.0, -4.0, 2.5)), gt)
    ate = absolute_trajectory_error(moved, gt)
    assert ate.rmse < 1e-9 and ate.max < 1e-9
    # The alignment found is the inverse of the applied motion.
    np.testing.assert_allclose(ate.alignment @ moved[5], gt[5], atol=1e-9)


def test_ate_measures_a_known_offset_and_does_not_fit_scale():
    gt = _wiggly_path()
    est = gt.copy()
    est[7, :3, 3] += [0.3, 0.0, 0.0]  # one bad pose
    ate = absolute_trajectory_error(est, gt)
    assert 0.0 < ate.rmse < 0.3
    assert ate.errors.argmax() == 7
    # A scaled trajectory is not rigidly alignable: SE3 alignment (no scale) must leave an error.
    scaled = gt.copy()
    scaled[:, :3, 3] *= 1.1
    assert absolute_trajectory_error(scaled, gt).rmse > 0.1


def test_rpe_hand_made_cases():
    gt = np.stack([_pose(), _pose(t=(1, 0, 0)), _pose(t=(2, 0, 0)), _pose((0, 0, np.pi / 2), (3, 0, 0))])
    rpe = relative_pose_errors(gt, gt)
    np.testing.assert_allclose(rpe.trans_errors, 0, atol=1e-12)
    np.testing.assert_allclose(rpe.rot_errors_deg, 0, atol=1e-6)
    est = gt.copy()
    est[2] = _pose(t=(2.1, 0, 0))  # pair 1->2 is 10 cm too long, pair 2->3 10 cm too short
    rpe = relative_pose_errors(est, gt)
    np.testing.assert_allclose(rpe.trans_errors, [0.0, 0.1, 0.1], atol=1e-9)
    est = gt.copy()
    est[3] = _pose((0, 0, np.radians(92)), (3, 0, 0))  # last pair rotates 2 degrees too far
    rpe = relative_pose_errors(est, gt)
    np.testing.assert_allclose(rpe.rot_errors_deg, [0, 0, 2.0], atol=1e-6)
    stats = rpe.stats()
    assert stats["rot_max_deg"] == pytest.approx(2.0, abs=1e-6)
    assert stats["rot_median_deg"] == pytest.approx(0.0, abs=1e-6)


def test_rpe_is_frame_independent_but_ate_is_not_fooled_by_drift():
    gt = _wiggly_path()
    # A constant per-step bias accumulates: RPE sees it per pair, ATE sees the drift.
    est = [gt[0]]
    for a, b in zip(gt[:-1], gt[1:]):
        est.append(est[-1] @ np.linalg.inv(a) @ b @ _pose(t=(0.01, 0, 0)))
    rpe = relative_pose_errors(np.stack(est), gt)
    np.testing.assert_allclose(rpe.trans_errors, 0.01, atol=1e-9)
    assert absolute_trajectory_error(np.stack(est), gt).max > 0.05


def test_mismatched_or_bad_inputs_raise():
    gt = _wiggly_path(5)
    with pytest.raises(ValueError, match="poses"):
        relative_pose_errors(gt[:4], gt)
    bad = gt.copy()
    bad[2, 0, 3] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        absolute_trajectory_error(bad, gt)
    with pytest.raises(ValueError, match="shape"):
        absolute_trajectory_error(np.zeros((3, 3, 3)), np.zeros((3, 3, 3)))


def test_associate_nearest_within_tolerance():
    ref = [0, 100, 200, 300]
    assert associate([101, 199, 400, -50], ref, max_dt_ns=10) == [1, 2, None, None]
    assert associate([5], [], max_dt_ns=10) == [None]
