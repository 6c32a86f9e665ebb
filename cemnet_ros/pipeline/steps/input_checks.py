"""Plausibility checks a scan passes before it may move the trajectory (no ROS: the node and the replay share it).

A registration can be judged only against a reference, and a reference is only as good as the scans that made
it: a scan with a fraction of the usual points (a sector, another sensor's), a corrupt stamp or a foreign frame
would be aligned somewhere and, worse, could become the reference. So each scan is checked first:

- **stamp**: nanoseconds within a second; not beyond ``future_tolerance`` ahead of the caller's clock; a stamp
  before the last one (out of order, a bag loop) or more than ``stamp_jump`` (and 20 periods) after it is
  refused unless the next scan confirms the new time base;
- **frame**: the trajectory's frame_id is the first scan's; another one is refused until a reset;
- **non-finite points** (NaN or inf in any coordinate: the no-returns of an organised cloud) are dropped first;
  however many there are, they never refuse a scan: the checks below judge the finite points alone (a sensor
  that turns to open sky has many more no-returns, and its returns are as trustworthy as before);
- **point count**: finite points against the running median of the recent scans (``min_count_ratio``), the
  azimuth sectors they cover against the recent coverage (``min_coverage_ratio``: a cropped sector); when a
  level stays unmet for ``relevel_after`` scans the sensor has changed and the levels restart, with a warning;
  a trajectory that began on a scan far smaller than the next ones restarts from the first representative one;
- **size**: more than ``max_points`` finite points are decimated (seeded), with a warning, never silently slow.

Rejections raise :class:`ScanRejected` with a ``kind`` the node counts; warnings travel with the admitted scan.
"""
from __future__ import annotations

import collections
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from cemnet_ros.pipeline.config import InputChecksConfig
from cemnet_ros.pipeline.errors import ScanRejected

SECTORS = 36  # azimuth bins of the coverage check
COVERAGE_SAMPLES = 16384  # points the coverage is counted on (a share per sector needs no more)
EARLY_LEVEL = 3  # a level from fewer scans than this may rest on an implausible start
UPWARD_RATIO = 4.0  # ... which shows as the next scan having this many times the points


@dataclass
class Admitted:
    """A scan that passed: its finite points (decimated if capped) and their times, what to tell the user, and
    whether the trajectory must restart from it (it began on an implausible scan)."""

    points: np.ndarray
    times: Optional[np.ndarray]
    stamp_ns: int
    frame_id: str
    n_finite: int
    coverage: float  # fraction of the azimuth sectors with points
    warnings: list[tuple[str, str]] = field(default_factory=list)  # (kind, message)
    restart: bool = False


def stamp_ns(sec: int, nanosec: int) -> int:
    """A header stamp in ns; ScanRejected when ``nanosec`` is not within a second (it would shift the stamp)."""
    if not 0 <= int(nanosec) < 1_000_000_000:
        raise ScanRejected(f"stamp nanosec {nanosec} is not in [0, 1e9)", "stamp")
    return int(sec) * 1_000_000_000 + int(nanosec)


class InputChecks:
    """The checks' state: the recent point counts and stamps, and the trajectory's frame."""

    def __init__(self, config: InputChecksConfig) -> None:
        self.config = config
        self._levels: collections.deque = collections.deque(maxlen=config.level_window)  # (count, coverage)
        self._low_in_a_row = 0
        self._frame_id: Optional[str] = None
        self._last_stamp: Optional[int] = None
        self._periods: collections.deque = collections.deque(maxlen=9)
        self._pending_jump: Optional[int] = None  # a refused jump's stamp, confirmed by a scan just after it

    def forget_frame(self) -> None:
        """A reset: the next scan's frame (and stamps) start the trajectory; the sensor's count level stays."""
        self._frame_id, self._last_stamp, self._pending_jump = None, None, None
        self._periods.clear()

    def admit(self, points: np.ndarray, times: Optional[np.ndarray], stamp_ns: int, frame_id: str = "",
              now_ns: Optional[int] = None) -> Admitted:
        """Check one scan (raises ScanRejected); call :meth:`passed` once the pipeline has used it.

        The admitted scan holds the finite points only (and their times): what the checks judged."""
        self._check_stamp(stamp_ns, now_ns)
        if frame_id and self._frame_id is not None and frame_id != self._frame_id:
            raise ScanRejected(f"frame_id {frame_id!r} is not the trajectory's {self._frame_id!r}: refused (a reset "
                               "starts over in the new frame)", "frame_id")
        points, times = _finite(points, times)
        admitted = Admitted(points, times, stamp_ns, frame_id, len(points), _coverage(points))
        self._check_levels(admitted)
        self._cap(admitted)
        return admitted

    def passed(self, admitted: Admitted) -> None:
        """The scan was used: it joins the count level, its stamp and frame become the reference."""
        stamp_ns = admitted.stamp_ns
        if admitted.restart:
            self._levels.clear()
        self._levels.append((admitted.n_finite, admitted.coverage))
        self._low_in_a_row = 0
        if self._last_stamp is not None and stamp_ns > self._last_stamp:
            self._periods.append(stamp_ns - self._last_stamp)
        self._last_stamp, self._pending_jump = stamp_ns, None
        self._frame_id = admitted.frame_id or self._frame_id

    def _check_stamp(self, stamp_ns: int, now_ns: Optional[int]) -> None:
        cfg = self.config
        if stamp_ns < 0:
            raise ScanRejected(f"stamp {stamp_ns * 1e-9:.3f} s is negative", "stamp")
        if now_ns is not None and cfg.future_tolerance > 0 and stamp_ns > now_ns + cfg.future_tolerance * 1e9:
            unset = " (the clock reads 0: a node with use_sim_time has had no /clock yet)" if now_ns == 0 else ""
            raise ScanRejected(f"stamp {stamp_ns * 1e-9:.3f} s is {(stamp_ns - now_ns) * 1e-9:.1f} s ahead of the "
                               f"clock{unset}", "stamp_future")
        if self._last_stamp is None or cfg.stamp_jump <= 0:
            return
        period = float(np.median(self._periods)) if self._periods else 0.0
        jump = stamp_ns - self._last_stamp
        if 0 <= jump <= max(cfg.stamp_jump * 1e9, 20.0 * period):
            return  # forward (a duplicate: the aligner skips it)
        pending, self._pending_jump = self._pending_jump, stamp_ns
        if pending is not None and 0 < stamp_ns - pending <= max(3.0 * period, 1e9):
            return  # the new time base is confirmed: the aligner sees a gap (or a restart) and handles it
        kind = "stamp_jump" if jump > 0 else "stamp_back"
        raise ScanRejected(f"stamp {'jumped' if jump > 0 else 'went back'} {abs(jump) * 1e-9:.3f} s from the last "
                           "scan: refused unless the next scan follows it", kind)

    def _check_levels(self, admitted: Admitted) -> None:
        cfg, n = self.config, admitted.n_finite
        if not self._levels or cfg.min_count_ratio <= 0:
            return
        count, coverage = np.median(np.asarray(self._levels), axis=0)
        if len(self._levels) < EARLY_LEVEL and n > UPWARD_RATIO * count:
            admitted.restart = True
            admitted.warnings.append(("implausible_start", f"the trajectory began on scans of ~{count:.0f} points, "
                                      f"this one has {n}: restarted from it (pose kept)"))
            return
        fault = _level_fault(admitted, cfg, count, coverage)
        if fault is None:
            return
        self._low_in_a_row += 1
        if self._low_in_a_row < cfg.relevel_after:
            raise ScanRejected(fault[1], fault[0])
        self._levels.clear()
        admitted.warnings.append(("relevel", f"{self._low_in_a_row} scans in a row: {fault[1]}: the sensor "
                                  "changed, the levels restart from this scan"))

    def _cap(self, admitted: Admitted) -> None:
        """More than ``max_points`` finite points: a seeded subset of them, in scan order, with a warning."""
        cap = self.config.max_points
        if cap <= 0 or admitted.n_finite <= cap:
            return
        keep = np.sort(np.random.default_rng(0).choice(admitted.n_finite, cap, replace=False))
        admitted.warnings.append(("decimated", f"{admitted.n_finite} finite points decimated to {cap} "
                                  "(input.max_points)"))
        admitted.points = admitted.points[keep]
        admitted.times = None if admitted.times is None else admitted.times[keep]


def _finite(points: np.ndarray, times: Optional[np.ndarray]) -> tuple[np.ndarray, Optional[np.ndarray]]:
    """The rows whose three coordinates are finite, and their times: a no-return (NaN or inf) is no point.

    Unchanged when all are (the decoded scans are: a 124k-point mask and copy per scan would cost milliseconds
    for nothing)."""
    if np.isfinite(points).all():
        return points, times
    finite = np.all(np.isfinite(points), axis=1)
    return points[finite], None if times is None else times[finite]


def _coverage(points: np.ndarray) -> float:
    """Fraction of the SECTORS azimuth sectors holding at least 2 % of a uniform share of the points (>= 3),
    counted on every k-th point (about COVERAGE_SAMPLES): each ring or row of a scan sweeps the azimuths."""
    if not len(points):
        return 0.0
    points = points[::max(1, len(points) // COVERAGE_SAMPLES)]
    azimuth = np.arctan2(points[:, 1], points[:, 0])
    sector = np.minimum(((azimuth + np.pi) * (SECTORS / (2 * np.pi))).astype(np.int64), SECTORS - 1)
    counts = np.bincount(sector, minlength=SECTORS)
    return float(np.mean(counts >= max(3.0, 0.02 * len(points) / SECTORS)))


def _level_fault(admitted: Admitted, cfg: InputChecksConfig, count: float, coverage: float
                 ) -> Optional[tuple[str, str]]:
    """(kind, message) of the first level the scan falls short of, None when it meets them all."""
    n = admitted.n_finite
    if n < cfg.min_count_ratio * count:
        return "point_count", f"{n} finite points, {n / count:.0%} of the recent median {count:.0f}"
    if admitted.coverage < cfg.min_coverage_ratio * coverage:
        return "coverage", (f"points in {admitted.coverage:.0%} of the azimuth sectors where {coverage:.0%} is "
                            "usual (a cropped sector?)")
    return None
