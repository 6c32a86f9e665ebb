"""6x6 pose covariance for nav_msgs/Odometry from the CEM's final sampling spread.

The CEM ends with a Gaussian N(mu, diag(sigma^2)) over actions ``[euler_z, euler_y, euler_x, tx, ty, tz]``
in network units; its spread is a direct, per-scan measure of how well the registration is constrained. ROS
orders covariance as ``x, y, z, roll, pitch, yaw``; for the small per-scan rotations the Euler angles z, y, x
are approximately yaw, pitch, roll (exact at zero rotation).
"""
from __future__ import annotations

import numpy as np

MIN_STD_TRANSLATION = 1e-3  # metres: the floor keeps the matrix positive definite for SLAM back ends
MIN_STD_ROTATION = 1e-3  # radians


def covariance_from_sigma(sigma: np.ndarray, scale: float, *, inflate: float = 1.0,
                          min_std_translation: float = MIN_STD_TRANSLATION,
                          min_std_rotation: float = MIN_STD_ROTATION) -> np.ndarray:
    """Diagonal ROS covariance from CEM sigma ``[z, y, x, tx, ty, tz]`` (rad, network units).

    ``scale`` is metres per network unit; ``inflate`` multiplies the variances (e.g. for a low-fitness step).
    """
    sigma = np.abs(np.asarray(sigma, dtype=np.float64).reshape(6))
    if not np.all(np.isfinite(sigma)):
        raise ValueError(f"sigma must be finite, got {sigma}")
    translation_std = np.maximum(sigma[3:] * float(scale), min_std_translation)
    roll_pitch_yaw_std = np.maximum(sigma[[2, 1, 0]], min_std_rotation)
    variances = np.concatenate([translation_std, roll_pitch_yaw_std]) ** 2 * float(inflate)
    return np.diag(variances)
