"""Trajectory metrics: ATE after rigid alignment, per-pair relative pose errors, stamp association.

Poses are 4x4 numpy matrices ``T_world_sensor`` (sensor pose in the world frame). Stamps are integer
nanoseconds. Everything here is pure numpy/scipy so it can score any odometry, not just CEMNet's. The TUM and
KITTI files are :mod:`cemnet_ros.io.trajectory_files`'.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from cemnet_ros.core.geometry import apply_transform, procrustes_np, rigid_transform, rotation_angle_deg
from cemnet_ros.io.trajectory_files import as_poses


@dataclass
class ATEResult:
    """Absolute trajectory error after the best rigid (SE3, no scale) alignment of estimate onto GT."""

    rmse: float  # metres
    mean: float
    median: float
    max: float
    errors: np.ndarray  # (n,) per-pose position error, metres
    alignment: np.ndarray  # (4,4) T_gt_est, from the estimate's world frame to the ground truth's: alignment @ est


@dataclass
class RPEResult:
    """Relative pose error of each consecutive pair (frame i -> i+1)."""

    trans_errors: np.ndarray  # (n-1,) metres
    rot_errors_deg: np.ndarray  # (n-1,) degrees

    def stats(self) -> dict:
        """Mean/median/max of the translation (m) and rotation (deg) errors (NaN when there is no pair)."""
        out = {}
        for name, unit, arr in (("trans", "m", self.trans_errors), ("rot", "deg", self.rot_errors_deg)):
            for fn in ("mean", "median", "max"):
                out[f"{name}_{fn}_{unit}"] = float(getattr(np, fn)(arr)) if arr.size else float("nan")
        return out


def _check_pair(est: np.ndarray, gt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    est, gt = as_poses(est), as_poses(gt)
    if len(est) != len(gt):
        raise ValueError(f"estimate has {len(est)} poses but ground truth has {len(gt)}")
    return est, gt


def absolute_trajectory_error(estimate: Sequence[np.ndarray], ground_truth: Sequence[np.ndarray]) -> ATEResult:
    """ATE of the positions after aligning the estimate onto the ground truth with a rigid transform."""
    est, gt = _check_pair(estimate, ground_truth)
    if len(est) == 0:
        raise ValueError("cannot compute ATE of an empty trajectory")
    T_gt_est = rigid_transform(*procrustes_np(est[:, :3, 3], gt[:, :3, 3]))
    err = np.linalg.norm(apply_transform(T_gt_est, est[:, :3, 3]) - gt[:, :3, 3], axis=1)
    return ATEResult(
        rmse=float(np.sqrt(np.mean(err**2))),
        mean=float(err.mean()),
        median=float(np.median(err)),
        max=float(err.max()),
        errors=err,
        alignment=T_gt_est,
    )


def relative_pose_errors(estimate: Sequence[np.ndarray], ground_truth: Sequence[np.ndarray]) -> RPEResult:
    """Per consecutive pair: error E = inv(G_i^-1 G_{i+1}) (P_i^-1 P_{i+1}); |t(E)| and angle(R(E))."""
    est, gt = _check_pair(estimate, ground_truth)
    trans, rot = [], []
    for i in range(len(est) - 1):
        T_prev_curr_est = np.linalg.inv(est[i]) @ est[i + 1]
        T_prev_curr_gt = np.linalg.inv(gt[i]) @ gt[i + 1]
        err = np.linalg.inv(T_prev_curr_gt) @ T_prev_curr_est
        trans.append(float(np.linalg.norm(err[:3, 3])))
        rot.append(rotation_angle_deg(err[:3, :3]))
    return RPEResult(np.asarray(trans, dtype=np.float64), np.asarray(rot, dtype=np.float64))


def associate(query_ns: Sequence[int], reference_ns: Sequence[int], max_dt_ns: int) -> list[int | None]:
    """Index into ``reference_ns`` of the stamp nearest each query stamp, None when farther than max_dt_ns."""
    ref = np.asarray(reference_ns, dtype=np.int64)
    if ref.size == 0:
        return [None] * len(query_ns)
    order = np.argsort(ref)
    ref_sorted = ref[order]
    out: list[int | None] = []
    for q in query_ns:
        k = int(np.searchsorted(ref_sorted, q))
        best = None
        for j in (k - 1, k):
            if 0 <= j < len(ref_sorted) and (best is None or abs(ref_sorted[j] - q) < abs(ref_sorted[best] - q)):
                best = j
        out.append(int(order[best]) if best is not None and abs(int(ref_sorted[best]) - int(q)) <= max_dt_ns else None)
    return out
