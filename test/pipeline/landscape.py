"""A hand-made landscape of basins standing in for a frame polished against a map (no engine, no scan)."""
from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
from street_scene import make_transform

from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.steps.health import disagreement
from cemnet_ros.pipeline.steps.refine import PolishResult

ITERS = 20
REACH = 0.2  # m: the fake fine polish's pairing distance
LENGTH = 10.0  # m: the lever arm that makes a rotation a distance (the fake frame's RMS range)


@dataclass
class Basin:
    pose: np.ndarray
    fitness: float
    coverage: float = 1.0


def at(x: float, yaw_deg: float = 0.0) -> np.ndarray:
    return make_transform(yaw=np.radians(yaw_deg), t=(x, 0.0, 0.0))


class Landscape:
    """A fake Polisher: the fine polish settles in the basin within REACH of its start (converged), else stays
    (its budget spent); the basin stage (GICP) finds any basin within 2 m; the map's overlap at a pose is its
    basin's fitness and coverage (0.1 and 0.5 between basins). ``last_scan``: where the basin stage leads from a
    pose it is given (the map's last scan disagrees with the map there), else the nearest basin."""

    def __init__(self, *basins: Basin, conditioning: float = 1.0,
                 last_scan: tuple[tuple[np.ndarray, np.ndarray], ...] = ()) -> None:
        self.basins, self.conditioning, self.last_scan = list(basins), conditioning, last_scan
        self.config, self.effort, self.iters, self.reach = AlignerConfig(), 1.0, ITERS, REACH
        self.reach_rad = REACH / LENGTH
        self.frame = SimpleNamespace(polish=np.zeros((10, 3)), polish_voxel=1.0, length=LENGTH)
        self.map = SimpleNamespace(overlap=lambda points, T, *limits: self.overlap(T), free_space=None)

    def _nearest(self, T: np.ndarray, radius: float):
        def apart(b: Basin) -> float:
            metres, radians = disagreement(b.pose, T)
            return metres + LENGTH * radians

        near = [b for b in self.basins if apart(b) <= radius]
        return min(near, key=apart) if near else None

    def fine(self, T_start: np.ndarray) -> PolishResult:
        basin = self._nearest(T_start, REACH)
        T = T_start if basin is None else basin.pose
        hessian = np.diag([self.conditioning * LENGTH ** 2, LENGTH ** 2, LENGTH ** 2, 1.0, 1.0, 1.0])
        return PolishResult(T.copy(), hessian, 1e-4, 500, ITERS if basin is None else 5)

    def basin(self, T_start: np.ndarray) -> np.ndarray:
        for T_from, T_to in self.last_scan:
            if np.allclose(T_from, T_start):
                return T_to.copy()
        basin = self._nearest(T_start, 2.0)
        return T_start if basin is None else basin.pose.copy()

    def within_reach(self, polish: PolishResult, T_pose: np.ndarray) -> bool:
        return polish.iterations < ITERS and np.linalg.norm(polish.T_target_source[:3, 3] - T_pose[:3, 3]) <= REACH

    def overlap(self, T: np.ndarray) -> tuple[float, float]:
        basin = self._nearest(T, 1e-6)
        return (0.1, 0.5) if basin is None else (basin.fitness, basin.coverage)
