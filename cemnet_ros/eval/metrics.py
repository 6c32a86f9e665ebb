"""Registration accuracy metrics, as reported by CEMNet / DCP, plus isotropic errors and recall.

Per pair: Euler errors ``[z, y, x]`` in degrees (difference of the 'zyx' angles of the predicted and the
true rotation, wrapped to [-180, 180)), their mean absolute and mean squared value over the 3 angles
(the reference's ``r_mae`` / ``r_mse``), the same for the translation components, the isotropic rotation
error (geodesic angle of ``R_gt^T R_pred``, degrees) and translation error (``||t_pred - t_gt||``).
Aggregates: MAE = mean of the per-pair MAE, RMSE = sqrt(mean of the per-pair MSE); recall = fraction of
pairs with rotation error < ``rot_thresh_deg`` and translation error < ``trans_thresh``.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Dict, Iterable, List

import numpy as np

from cemnet_ros.core.geometry import matrix_to_euler_np, rotation_angle_deg

RECALL_ROT_DEG = 1.0
RECALL_TRANS = 0.01


@dataclass
class PairMetrics:
    """Errors of one registration result against its ground truth."""

    r_mae_deg: float  # mean |Euler error| over [z, y, x]
    r_mse_deg2: float  # mean squared Euler error over [z, y, x]
    t_mae: float
    t_mse: float
    rot_err_deg: float  # isotropic (geodesic) rotation error
    trans_err: float  # isotropic translation error (Euclidean norm)

    def as_dict(self) -> Dict[str, float]:
        return asdict(self)


def euler_error_deg(rotation_pred: np.ndarray, rotation_gt: np.ndarray) -> np.ndarray:
    """Per-angle error ``[z, y, x]`` in degrees between two rotations, wrapped to [-180, 180)."""
    diff = np.degrees(matrix_to_euler_np(rotation_pred) - matrix_to_euler_np(rotation_gt))
    return (diff + 180.0) % 360.0 - 180.0


def pair_metrics(rotation_pred: np.ndarray, translation_pred: np.ndarray,
                 rotation_gt: np.ndarray, translation_gt: np.ndarray) -> PairMetrics:
    """All per-pair errors of a prediction ``target ~= R_pred source + t_pred``."""
    rotation_pred = np.asarray(rotation_pred, dtype=np.float64)
    rotation_gt = np.asarray(rotation_gt, dtype=np.float64)
    if rotation_pred.shape != (3, 3) or rotation_gt.shape != (3, 3):
        raise ValueError("rotations must be (3, 3) matrices")
    t_diff = np.asarray(translation_pred, dtype=np.float64) - np.asarray(translation_gt, dtype=np.float64)
    if t_diff.shape != (3,):
        raise ValueError("translations must be (3,) vectors")
    if not (np.isfinite(rotation_pred).all() and np.isfinite(t_diff).all()):
        raise ValueError("the prediction has non-finite values")
    e = euler_error_deg(rotation_pred, rotation_gt)
    return PairMetrics(
        r_mae_deg=float(np.mean(np.abs(e))), r_mse_deg2=float(np.mean(e ** 2)),
        t_mae=float(np.mean(np.abs(t_diff))), t_mse=float(np.mean(t_diff ** 2)),
        rot_err_deg=rotation_angle_deg(rotation_gt.T @ rotation_pred), trans_err=float(np.linalg.norm(t_diff)),
    )


def aggregate(metrics: Iterable[PairMetrics], rot_thresh_deg: float = RECALL_ROT_DEG,
              trans_thresh: float = RECALL_TRANS) -> Dict[str, float]:
    """Dataset-level figures from per-pair metrics (see the module docstring)."""
    items: List[PairMetrics] = list(metrics)
    if not items:
        raise ValueError("cannot aggregate metrics of zero pairs")
    col = {name: np.array([getattr(m, name) for m in items]) for name in PairMetrics.__dataclass_fields__}
    success = (col["rot_err_deg"] < rot_thresh_deg) & (col["trans_err"] < trans_thresh)
    return {
        "n_pairs": len(items),
        "r_mae_deg": float(col["r_mae_deg"].mean()),
        "r_rmse_deg": float(np.sqrt(col["r_mse_deg2"].mean())),
        "t_mae": float(col["t_mae"].mean()),
        "t_rmse": float(np.sqrt(col["t_mse"].mean())),
        "rot_err_deg_mean": float(col["rot_err_deg"].mean()),
        "rot_err_deg_median": float(np.median(col["rot_err_deg"])),
        "trans_err_mean": float(col["trans_err"].mean()),
        "trans_err_median": float(np.median(col["trans_err"])),
        "recall": float(success.mean()),
        "recall_rot_thresh_deg": float(rot_thresh_deg),
        "recall_trans_thresh": float(trans_thresh),
    }
