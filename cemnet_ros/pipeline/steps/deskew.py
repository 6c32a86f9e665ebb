"""Motion compensation (deskewing) of a LiDAR sweep, and the per-point time convention it relies on.

A spinning LiDAR measures its points over a sweep (~0.1 s) while it moves: point i is expressed in the sensor
frame at its own time t_i, so a scan taken at 15 m/s is smeared by 1.5 m. :func:`deskew` moves every point into
the sensor frame at one instant, assuming a constant body velocity (the motion model's) over the sweep.

**Time convention** (everywhere in the package): per-point times are float64 **seconds relative to the cloud's
header stamp** (negative = before it). :func:`normalize_point_times` turns a raw PointCloud2 time field into it.

**No normalisation, no guess of where the stamp lies.** The relative time fields of the ROS drivers are offsets
from the header stamp already (Ouster ``t``: ns from the first column, which the stamp is; Velodyne ``time``: s,
negative when the driver stamps with the last packet, its default), and absolute fields (Hesai, Livox) are made
relative to it; so wherever a driver puts its stamp, the times say it. KISS-ICP instead min-max normalises them to
[0, 1] and deskews to a fixed fraction (0.5 once, 1.0 now): that drops the sweep's real duration (the velocity is
per stamp interval, which need not be the sweep's) and presumes the stamp's place in the sweep.

:func:`deskew` moves the points to the instant their times are relative to (the stamp, or any reference: shift
the times). The pipeline (:class:`~cemnet_ros.pipeline.steps.sweep.SweepDeskewer`) deskews to
the sweep's middle, where a registration pins the pose whatever the velocity used, and publishes the pose at
the stamp.
"""
from __future__ import annotations

from typing import Callable, Optional

import numpy as np

from cemnet_ros.core.geometry import exp_coefficients, se3_log

# Time field names, in order of preference when a cloud has several (relative offsets first: no precision loss).
TIME_FIELDS = ("t", "time", "offset_time", "timestamp")
MAX_OFFSET_S = 1.0  # a point's time this far from the stamp is implausible: the field was misread
MIN_NANOSECONDS = 1e3  # a float field read as relative ns must reach 1 us (else it is a misread seconds field)


class TimeFieldError(ValueError):
    """Per-point times that fit no known convention (e.g. an unknown unit): better no deskew than a wrong one."""


def normalize_point_times(raw: np.ndarray, stamp_ns: int, name: str = "time",
                          max_offset: float = MAX_OFFSET_S) -> np.ndarray:
    """Raw per-point times -> float64 seconds relative to the stamp ``stamp_ns`` (integer nanoseconds).

    The unit follows the dtype, then the magnitude, the first plausible reading winning (every finite time
    within ``max_offset`` s of the stamp):

    * integer fields: **nanoseconds relative to the stamp** (Ouster ``t``, Livox ``offset_time``: uint32 ns);
    * float fields, in this order: seconds relative to the stamp (Velodyne ``time``, float32, <= 0 when stamped
      at the sweep's end); absolute seconds (Hesai/Robosense ``timestamp``, float64; also absolute sim time);
      absolute nanoseconds (Livox driver 2 ``timestamp``, float64); nanoseconds relative to the stamp (the old
      Ouster driver's float ``t``; only for values reaching ``MIN_NANOSECONDS``: 7.5 is a misread, not 7.5 ns).

    Non-finite times become 0 (the point is left where it is). Raises :class:`TimeFieldError` when no reading
    is plausible.
    """
    values = np.asarray(raw).reshape(-1)
    stamp_ns = int(stamp_ns)
    readings = _readings(values.dtype, stamp_ns, name)
    finite = np.isfinite(values) if values.dtype.kind == "f" else np.ones(len(values), dtype=bool)
    if not np.any(finite):
        return np.zeros(len(values), dtype=np.float64)
    largest = float(np.max(np.abs(values[finite].astype(np.float64))))
    for _, convert, least in readings:
        times = np.zeros(len(values), dtype=np.float64)
        times[finite] = convert(values[finite])
        if largest >= least and np.max(np.abs(times[finite])) <= max_offset:
            return times
    lo, hi = (float(np.min(values[finite])), float(np.max(values[finite])))
    tried = ", ".join(label for label, _, _ in readings)
    raise TimeFieldError(f"time field {name!r} ({values.dtype}, values {lo:.6g}..{hi:.6g}, stamp "
                         f"{stamp_ns * 1e-9:.9f} s) fits no convention within {max_offset} s of the stamp "
                         f"(tried: {tried})")


def _readings(dtype: np.dtype, stamp_ns: int, name: str) -> list[tuple[str, Callable, float]]:
    """The plausible readings of a time field of ``dtype``, in order: (label, conversion to seconds relative
    to the stamp, least max |value| it needs: small floats are never nanoseconds)."""
    stamp_s = stamp_ns * 1e-9
    if dtype.kind in "iu":
        return [("nanoseconds relative to the stamp", lambda v: v.astype(np.float64) * 1e-9, 0.0)]
    if dtype.kind == "f":
        return [
            ("seconds relative to the stamp", lambda v: v.astype(np.float64), 0.0),
            ("absolute seconds", lambda v: v.astype(np.float64) - stamp_s, 0.0),
            ("absolute nanoseconds", lambda v: (v.astype(np.float64) - float(stamp_ns)) * 1e-9, 0.0),
            ("nanoseconds relative to the stamp", lambda v: v.astype(np.float64) * 1e-9, MIN_NANOSECONDS),
        ]
    raise TimeFieldError(f"time field {name!r} has dtype {dtype}, not an integer or float")


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
