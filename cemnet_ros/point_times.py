"""Per-point times of a LiDAR sweep: the package's convention, and reading a PointCloud2 time field into it.

**Time convention** (everywhere in the package): per-point times are float64 **seconds relative to the cloud's
header stamp** (negative = before it). :func:`normalize_point_times` turns a raw time field into it.

**No normalisation, no guess of where the stamp lies.** The relative time fields of the ROS drivers are offsets
from the header stamp already (Ouster ``t``: ns from the first column, which the stamp is; Velodyne ``time``: s,
negative when the driver stamps with the last packet, its default), and absolute fields (Hesai, Livox) are made
relative to it; so wherever a driver puts its stamp, the times say it. KISS-ICP instead min-max normalises them to
[0, 1] and deskews to a fixed fraction of the sweep: that drops the sweep's real duration (the velocity is per
stamp interval, which need not be the sweep's) and presumes the stamp's place in the sweep.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

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
