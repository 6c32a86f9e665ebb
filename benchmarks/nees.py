"""Consistency of a published covariance against ground truth: the normalised estimation error squared (NEES).

The node's pose covariance (docs/node.md, "Covariance") is that of one step: the error of ``T_odom_base_k``
given ``T_odom_base_{k-1}``, as a rotation vector ``w`` about the base's position in odom axes
(R <- exp([w]x) R) and a translation ``v`` in odom axes (t <- t + v), ROS order [v, w]. :func:`step_error` is
that error against the true motion; NEES = e^T Sigma^-1 e follows a chi-square law of 6 degrees of freedom for
a consistent estimator: mean 6, 95 % of the steps below :data:`CHI2_95` [6].
"""
from __future__ import annotations

from typing import Optional

import numpy as np
from scipy.stats import chi2

from cemnet_ros.core.geometry import so3_log

CHI2_95 = {dof: float(chi2.ppf(0.95, dof)) for dof in (3, 6)}  # 7.81 and 12.59
TRANSLATION, ROTATION = slice(0, 3), slice(3, 6)  # blocks of a ROS-order error / covariance


def step_error(T_odom_prev: np.ndarray, T_odom_curr: np.ndarray, T_world_prev_true: np.ndarray,
               T_world_curr_true: np.ndarray) -> np.ndarray:
    """(6,) ROS order [v, w]: the published ``T_odom_curr`` against the pose the true motion gives from the
    published ``T_odom_prev`` (the step's own error, in the covariance's parameterisation and frame)."""
    T_odom_curr_true = T_odom_prev @ np.linalg.inv(T_world_prev_true) @ T_world_curr_true
    w = so3_log(T_odom_curr[:3, :3] @ T_odom_curr_true[:3, :3].T)
    return np.r_[T_odom_curr[:3, 3] - T_odom_curr_true[:3, 3], w]


def nees(error: np.ndarray, covariance: np.ndarray, block: slice = slice(0, 6)) -> float:
    """e^T Sigma^-1 e over ``block`` of a ROS-order error and covariance (the marginal of that block)."""
    e, sigma = error[block], covariance[block, block]
    return float(e @ np.linalg.solve(sigma, e))


def consistency(values: list[float], dof: int = 6) -> dict[str, Optional[float]]:
    """Mean and median NEES, the share of steps below the 95 % chi-square bound, and the mean over the expected
    value (``dof``): > 1 over-confident, < 1 under-confident. None for no steps."""
    if not values:
        return {"steps": 0, "mean": None, "median": None, "within_95": None, "ratio": None}
    arr = np.asarray(values, dtype=np.float64)
    return {"steps": len(arr), "mean": float(arr.mean()), "median": float(np.median(arr)),
            "within_95": float(np.mean(arr <= CHI2_95[dof])), "ratio": float(arr.mean() / dof)}


def step_consistency(errors: list[np.ndarray], covariances: list[np.ndarray]) -> dict[str, dict]:
    """:func:`consistency` of the full 6-D NEES and of its translation and rotation blocks (3 dof each)."""
    return {name: consistency([nees(e, c, block) for e, c in zip(errors, covariances)], dof)
            for name, block, dof in (("pose", slice(0, 6), 6), ("translation", TRANSLATION, 3),
                                     ("rotation", ROTATION, 3))}
