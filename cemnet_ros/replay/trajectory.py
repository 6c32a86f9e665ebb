"""Trajectory metrics and I/O: TUM files, ATE after rigid alignment, per-pair relative pose errors.

Poses are 4x4 numpy matrices ``T_world_sensor`` (sensor pose in the world frame). Stamps are integer
nanoseconds. Everything here is pure numpy/scipy so it can score any odometry, not just CEMNet's.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from cemnet_ros.core.geometry import apply_transform, procrustes_np, rigid_transform, rotation_angle_deg
from cemnet_ros.io.atomic import atomic_write_text


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


def _as_poses(poses: Sequence[np.ndarray] | np.ndarray) -> np.ndarray:
    arr = np.asarray(poses, dtype=np.float64)
    if arr.ndim != 3 or arr.shape[1:] != (4, 4):
        raise ValueError(f"poses must have shape (n, 4, 4), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError("poses contain NaN or inf")
    return arr


def _check_pair(est: np.ndarray, gt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    est, gt = _as_poses(est), _as_poses(gt)
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


def pose_to_tum_row(stamp_ns: int, pose: np.ndarray) -> str:
    """One TUM line: ``timestamp tx ty tz qx qy qz qw`` (timestamp in seconds)."""
    qx, qy, qz, qw = Rotation.from_matrix(pose[:3, :3]).as_quat()
    tx, ty, tz = pose[:3, 3]
    return f"{stamp_ns // 1_000_000_000}.{stamp_ns % 1_000_000_000:09d} " + " ".join(
        f"{v:.9f}" for v in (tx, ty, tz, qx, qy, qz, qw)
    )


def write_tum(path: str | os.PathLike, stamps_ns: Sequence[int], poses: Sequence[np.ndarray]) -> Path:
    """Write a TUM trajectory file atomically (temporary file in the same directory, then rename)."""
    arr = _as_poses(poses) if len(poses) else np.zeros((0, 4, 4))
    if len(stamps_ns) != len(arr):
        raise ValueError(f"{len(stamps_ns)} stamps but {len(arr)} poses")
    if any(int(s) < 0 for s in stamps_ns):
        raise ValueError("TUM stamps must be >= 0")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = "# timestamp tx ty tz qx qy qz qw\n" + "".join(
        pose_to_tum_row(int(s), p) + "\n" for s, p in zip(stamps_ns, arr)
    )
    atomic_write_text(path, text)
    return path


def read_tum(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM file -> (stamps_ns (n,) int64, poses (n,4,4)). Raises ValueError on malformed lines."""
    stamps, poses = [], []
    for lineno, line in enumerate(Path(path).read_text().splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.split()
        if len(parts) != 8:
            raise ValueError(f"{path}:{lineno}: expected 8 columns, got {len(parts)}")
        try:
            vals = [float(v) for v in parts[1:]]
            sec, _, frac = parts[0].partition(".")
            stamp = int(sec) * 1_000_000_000 + int((frac + "000000000")[:9] or 0)
        except ValueError as err:
            raise ValueError(f"{path}:{lineno}: {err}") from None
        stamps.append(stamp)
        poses.append(rigid_transform(Rotation.from_quat(vals[3:]).as_matrix(), vals[:3]))
    return np.asarray(stamps, dtype=np.int64), np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
