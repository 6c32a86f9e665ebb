"""Motion compensation (deskewing) of a LiDAR sweep.

A spinning LiDAR measures its points over a sweep (~0.1 s) while it moves: point i is expressed in the sensor
frame at its own time t_i, so a scan taken at 15 m/s is smeared by 1.5 m. :func:`deskew` moves every point into
the sensor frame at one instant, assuming a constant body velocity (the motion model's) over the sweep.

Per-point times are float64 seconds relative to the cloud's header stamp (:mod:`cemnet_ros.point_times` reads
them from a PointCloud2 time field). :func:`deskew` moves the points to the instant their times are relative to
(the stamp, or any reference: shift the times). The pipeline
(:class:`~cemnet_ros.pipeline.steps.sweep.SweepDeskewer`) deskews to the sweep's middle, where a registration
pins the pose whatever the velocity used, and publishes the pose at the stamp.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from cemnet_ros.core.geometry import exp_coefficients, se3_log


def deskew(points: np.ndarray, times: np.ndarray, T_prev_curr: Optional[np.ndarray], dt: float,
           twist: Optional[np.ndarray] = None) -> np.ndarray:
    """Points measured at their own times ``times`` (s, relative to the stamp) -> the sensor frame at the stamp.

    Constant body velocity: ``T_prev_curr`` (the motion over the last ``dt`` seconds, e.g. the constant-velocity
    prediction) gives the twist xi = log(T_prev_curr) / dt, the sensor at time t relative to the stamp is
    T(t) = exp(t xi), and p' = T(t_i) p_i. Exact for a constant-velocity motion (the SE(3) exponential in
    closed form, per point). ``twist`` (per second) may be given instead of recomputing it from the transform.
    Returns a new (n, 3) float64 array; a zero velocity or zero times give the points back unchanged.
    """
    pts = np.asarray(points, dtype=np.float64)
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(t) != len(pts):
        raise ValueError(f"points must be (n, 3) and times (n,), not {pts.shape} and {t.shape}")
    if twist is None:
        if T_prev_curr is None or not dt > 0:
            raise ValueError(f"without a twist, T_prev_curr and dt > 0 are needed (dt = {dt})")
        twist = se3_log(T_prev_curr) / dt
    xi = np.asarray(twist, dtype=np.float64)
    if not np.any(xi) or not np.any(t):
        return pts.copy()
    # exp(t xi) with xi = (r, w): rotation vector t w, so every cross product is t^k times a constant one:
    # p' = p + a t (w x p) + b t^2 (w x (w x p) + w x r) + t r + c t^3 w x (w x r)  (Rodrigues, then V(t w) t r).
    # Written element-wise: an (n, 3) @ (3, 3) product goes through multithreaded BLAS, slow on a busy machine.
    r, w = xi[:3], xi[3:]
    a, b, c = exp_coefficients(np.abs(t) * np.linalg.norm(w))
    a *= t
    b *= t * t
    c *= t ** 3
    x, y, z = pts[:, 0], pts[:, 1], pts[:, 2]
    dot = x * w[0] + y * w[1] + z * w[2]  # w . p
    wr = np.cross(w, r)
    wwr = np.cross(w, wr)
    out = np.empty_like(pts)
    for k, (i, j) in enumerate(((1, 2), (2, 0), (0, 1))):
        cross_k = w[i] * pts[:, j] - w[j] * pts[:, i]  # (w x p)_k
        double_k = w[k] * dot - (w @ w) * pts[:, k]  # (w x (w x p))_k
        out[:, k] = pts[:, k] + a * cross_k + b * (double_k + wr[k]) + t * r[k] + c * wwr[k]
    return out
