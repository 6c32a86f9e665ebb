"""Deskewing across scans (step 1 of the recipe in :mod:`..aligner`): the sweep's reference time, the map's
first scans, the pose at the stamp.

With per-point times and ``preprocess.deskew`` a scan is registered at the sweep's middle (fixed from the first
timed scan: a driver's stamping policy does not change) with its points moved there at the motion model's
velocity. Not at the stamp: a registration pins the pose at the points' mean time, the pose elsewhere rests on
the velocity; were the reference the sweep's start (Ouster's stamp), a velocity error would bias the pose, the
next velocity would carry the opposite error and so on, undamped. At the middle the pose does not depend on the
velocity used; :meth:`SweepDeskewer.at_stamp` publishes the pose at the stamp. The first scans of a trajectory
have no velocity: once one is known, the map is rebuilt from them deskewed (the map keeps the first points of a
voxel for good: skewed ones would bias every later step).
"""
from __future__ import annotations

from typing import Callable, Optional

import numpy as np

from cemnet_ros.core.geometry import apply_transform, se3_exp
from cemnet_ros.pipeline.errors import ScanRejected
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.steps.alignment_step import AlignmentStep
from cemnet_ros.pipeline.steps.deskew import deskew
from cemnet_ros.pipeline.steps.frame import Preprocessor

SkewedScan = tuple[np.ndarray, np.ndarray]  # points, times relative to the reference (s)
Velocity = Callable[[], Optional[np.ndarray]]  # the motion model's twist (6,) per second, None: none yet


class SweepDeskewer:
    """The deskewing state of one trajectory (see the module docstring)."""

    def __init__(self, enabled: bool, preprocessor: Preprocessor) -> None:
        self.enabled = enabled
        self.preprocessor = preprocessor
        self.reset()

    def reset(self) -> None:
        self._sweep_offset_ns: Optional[int] = None  # the reference time's offset from the stamps
        self._published: Optional[np.ndarray] = None  # the last pose published (at its stamp)
        self._odom_fix: Optional[np.ndarray] = None  # T_odom_reference0 (odom: the first scan's stamp)
        self._skewed_input: Optional[SkewedScan] = None  # this scan, timed but not deskewed
        self._inserted: Optional[list] = None  # the map's scans while none could be deskewed (None: not tracked)

    def deskewed(self, points: np.ndarray, point_times: Optional[np.ndarray], stamp_ns: int,
                 velocity: Velocity, last_stamp: Optional[int], local_map: Optional[VoxelMap]
                 ) -> tuple[np.ndarray, int, Optional[VoxelMap]]:
        """(points, offset ns, map): the scan in the sensor frame at its reference time ``stamp_ns + offset``.

        ``velocity`` is asked only for a timed scan; ``last_stamp``: the last reference time registered. The
        map comes back rebuilt when this is the first scan deskewed.
        """
        self._skewed_input = None
        if not self.enabled or (point_times is None and self._sweep_offset_ns is None):
            return points, 0, local_map
        if self._sweep_offset_ns is None:
            times = np.asarray(point_times, dtype=np.float64)
            self._sweep_offset_ns = int(round(0.5 * (times.min() + times.max()) * 1e9)) if times.size else 0
        offset_ns = self._sweep_offset_ns
        if point_times is None:
            return points, offset_ns, local_map
        times = np.asarray(point_times, dtype=np.float64) - offset_ns * 1e-9
        twist = velocity()
        if twist is None or last_stamp is None or stamp_ns + offset_ns <= last_stamp:
            self._skewed_input = (np.asarray(points), times)  # no velocity yet, a duplicate or a restart
            return points, offset_ns, local_map
        if self._inserted:
            rebuilt = self._redeskewed_map(twist)
            local_map = local_map if rebuilt is None else rebuilt
        self._inserted = None
        return deskew(points, times, None, 0.0, twist=twist), offset_ns, local_map

    def map_restarted(self, T_odom_sensor: np.ndarray) -> None:
        """A new map starts from this scan: remember its scans until they can be deskewed."""
        self._inserted = []
        self.inserted(T_odom_sensor)

    def inserted(self, T_odom_sensor: np.ndarray) -> None:
        """This scan went into the map at ``T_odom_sensor``. One without times (or deskewed already) ends the
        tracking of undeskewed scans: the map cannot be rebuilt without it."""
        if self._inserted is not None:
            if self._skewed_input is None:
                self._inserted = None
            else:
                self._inserted.append((*self._skewed_input, T_odom_sensor.copy()))

    def moved(self, T_correction: np.ndarray) -> None:
        """The trajectory moved by ``T_correction`` (the internal odom frame, from the left): the last pose
        published moves with it, so that the next step's motion does not count the move."""
        if self._published is not None:
            fix = np.eye(4) if self._odom_fix is None else self._odom_fix
            self._published = fix @ T_correction @ np.linalg.inv(fix) @ self._published

    def _redeskewed_map(self, twist: np.ndarray) -> Optional[VoxelMap]:
        """The map rebuilt from its scans (all of them went in undeskewed) deskewed at the first velocity known;
        None when one of them no longer passes preprocessing (the map is kept as it is)."""
        rebuilt = self.preprocessor.new_map()
        for points, times, pose in self._inserted or ():
            try:
                dense = self.preprocessor.frame(deskew(points, times, None, 0.0, twist=twist)).dense
            except ScanRejected:
                return None
            rebuilt.update(apply_transform(pose, dense), pose[:3, 3])
        return rebuilt

    def at_stamp(self, step: AlignmentStep, stamp_ns: int, offset_ns: int, velocity: Velocity,
                 has_velocity: bool) -> AlignmentStep:
        """The step as published: the pose at ``stamp_ns`` (the reference time is ``offset_ns`` later).

        The internal poses are the reference times'; odom stays the sensor frame at the first scan's stamp,
        placed by the first velocity known (none is known at the first scan itself; ``has_velocity``: the
        motion model knows one; ``velocity()`` is None without a time step to scale it).
        """
        if offset_ns:
            twist = velocity()
            to_stamp = np.eye(4) if twist is None else se3_exp(twist * (-offset_ns * 1e-9))
            if self._odom_fix is None and has_velocity:
                self._odom_fix = np.linalg.inv(to_stamp)
            step.pose = (self._odom_fix if self._odom_fix is not None else np.eye(4)) @ step.pose @ to_stamp
            if step.relative is not None and self._published is not None:
                step.relative = np.linalg.inv(self._published) @ step.pose
            step.stamp_ns = stamp_ns
        self._published = step.pose
        return step
