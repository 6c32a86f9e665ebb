"""Pose covariance of a registration from the point-to-plane polish's Hessian, and its degenerate directions.

The polish minimises sum w_i r_i^2 over the perturbation [w, v]: R <- exp([w]x) R, t <- t + v (rotation about
the sensor's position, axes of the map frame). At the optimum the covariance of [w, v] is sigma^2 H^-1, with
sigma^2 the residual variance. Along a direction the scene does not constrain (a corridor's axis) the Hessian's
eigenvalue is near zero: the pipeline keeps the motion prediction there and the covariance reports the
prediction's uncertainty instead, so it grows along the corridor. ROS orders covariance x, y, z, roll, pitch,
yaw: [v, w] here (rotation-vector components about the map axes, which are roll, pitch, yaw for small angles).

A step's covariance (this registration's plus :func:`carried_into_step`) is that of its motion, not of one
registration: the map holds the earlier scans where they were registered, so the previous pose errs against the
map by its own registration's error, and the motion between the two poses carries both.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cemnet_ros.core.geometry import hat, so3_exp, so3_log

MIN_STD_TRANSLATION = 1e-3  # metres: the floor keeps the matrix positive definite for SLAM back ends
MIN_STD_ROTATION = 1e-3  # radians
ROS_ORDER = [3, 4, 5, 0, 1, 2]  # [w, v] -> x, y, z, roll, pitch, yaw


@dataclass
class Conditioning:
    """Eigen-decomposition of the Hessian with rotations scaled to metres by ``length``."""

    eigenvalues: np.ndarray  # (6,) ascending
    eigenvectors: np.ndarray  # (6, 6) columns, in normalised coordinates [w * length, v]
    length: float

    @classmethod
    def of(cls, hessian: np.ndarray, length: float) -> "Conditioning":
        scale = np.r_[np.full(3, 1.0 / length), np.ones(3)]
        values, vectors = np.linalg.eigh(hessian * np.outer(scale, scale))
        return cls(np.maximum(values, 0.0), vectors, float(length))

    @property
    def ratio(self) -> float:
        """lambda_min / lambda_max (0 = a free direction, 1 = constrained alike in every direction)."""
        return float(self.eigenvalues[0] / self.eigenvalues[-1]) if self.eigenvalues[-1] > 0 else 0.0

    def degenerate_basis(self, min_ratio: float) -> np.ndarray:
        """(6, k) normalised directions whose eigenvalue is below ``min_ratio`` times the largest."""
        return self.eigenvectors[:, self.eigenvalues < min_ratio * self.eigenvalues[-1]]


def keep_prediction_along(basis: np.ndarray, length: float, T_predicted: np.ndarray, T_registered: np.ndarray
                          ) -> np.ndarray:
    """T_registered with its difference to T_predicted removed along the normalised ``basis`` directions."""
    delta = np.r_[so3_log(T_registered[:3, :3] @ T_predicted[:3, :3].T) * length,
                  T_registered[:3, 3] - T_predicted[:3, 3]]
    delta -= basis @ (basis.T @ delta)
    out = np.eye(4)
    out[:3, :3] = so3_exp(delta[:3] / length) @ T_predicted[:3, :3]
    out[:3, 3] = T_predicted[:3, 3] + delta[3:]
    return out


def covariance_from_hessian(conditioning: Conditioning, residual_variance: float, degenerate_variance: float,
                            min_ratio: float, *, inflate: float = 1.0) -> np.ndarray:
    """6x6 ROS covariance: sigma^2 H^-1, the free directions given ``degenerate_variance`` (m^2, normalised)."""
    values = conditioning.eigenvalues
    floor = max(values[-1], 1e-12) * min_ratio
    variances = np.where(values >= floor, residual_variance / np.maximum(values, 1e-12), degenerate_variance)
    vectors = conditioning.eigenvectors
    normalised = (vectors * variances) @ vectors.T
    scale = np.r_[np.full(3, 1.0 / conditioning.length), np.ones(3)]
    cov = normalised * np.outer(scale, scale)  # back to [w (rad), v (m)]
    cov = cov[np.ix_(ROS_ORDER, ROS_ORDER)] * float(inflate)
    floor_std = np.r_[np.full(3, MIN_STD_TRANSLATION), np.full(3, MIN_STD_ROTATION)]
    return cov + np.diag(floor_std ** 2)


def flat_covariance(std_translation: float, std_rotation: float, *, inflate: float = 1.0) -> np.ndarray:
    """Diagonal ROS covariance (e.g. a step without a polish, or the first scan)."""
    std = np.r_[np.full(3, max(std_translation, MIN_STD_TRANSLATION)), np.full(3, max(std_rotation, MIN_STD_ROTATION))]
    return np.diag(std ** 2) * float(inflate)


def moved_by(covariance: np.ndarray, lever_odom: np.ndarray) -> np.ndarray:
    """A ROS-order pose covariance (rotations about the pose's position) as the error it makes at a position
    ``lever_odom`` (m, odom axes) away: a rotation error w moves that position by w x lever."""
    jacobian = np.eye(6)
    jacobian[:3, 3:] = -hat(lever_odom)
    return jacobian @ covariance @ jacobian.T


def carried_into_step(previous_vs_map: np.ndarray, T_odom_previous: np.ndarray, T_odom_current: np.ndarray
                      ) -> np.ndarray:
    """What the previous pose's error adds to the covariance of the step from ``T_odom_previous`` to
    ``T_odom_current`` (ROS order, about the current position): ``previous_vs_map``, the previous pose's error
    against the map (its own registration's, independent of this one; zero where the map was started from it),
    moved to the current position. The step's covariance is this registration's plus it."""
    return moved_by(previous_vs_map, T_odom_current[:3, 3] - T_odom_previous[:3, 3])
