"""The engine in metres: a frame's clouds and poses carried into the engine's units and its answers back.

The CEM and the global search work on the ModelNet unit sphere (epsilon = 0.1); a scan is in metres. Both the
tracking CEM and the recovery's search see the scan through one :class:`EngineUnits`: scaled by the
trajectory's scale, centred on a point near the sensor (the search's yaw then turns about the sensor).
"""
from __future__ import annotations

import numpy as np

from cemnet_ros.core.geometry import apply_transform
from cemnet_ros.pipeline.steps.frame import Frame


class EngineUnits:
    """Metres <-> the engine's units at ``frame``'s scale, centred on ``centre`` (3,) m."""

    def __init__(self, frame: Frame, centre: np.ndarray) -> None:
        self.to_units, self.from_units = frame.network_units(centre)
        self.scale = frame.scale

    def points(self, xyz_m: np.ndarray) -> np.ndarray:
        """Points (n, 3) in metres, in units."""
        return apply_transform(self.to_units, xyz_m)

    def pose(self, T_m: np.ndarray) -> np.ndarray:
        """A transform between two metric frames, as the engine sees it."""
        return self.to_units @ np.asarray(T_m, dtype=np.float64) @ self.from_units

    def pose_in_metres(self, T_units: np.ndarray) -> np.ndarray:
        """An engine's answer (4x4 in units), in metres (the bottom row made exact)."""
        T_m = self.from_units @ np.asarray(T_units, dtype=np.float64) @ self.to_units
        T_m[3] = (0.0, 0.0, 0.0, 1.0)
        return T_m

    def sigma(self, rotation_rad: float, translation_m: float) -> np.ndarray:
        """The engine's 6-D spread [Euler z, y, x (rad), t (units)] of these metric spreads."""
        return np.r_[np.full(3, rotation_rad), np.full(3, translation_m / self.scale)]
