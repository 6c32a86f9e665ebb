"""Polishing a start against the map (metres): the precision of every answer tracking and the recovery publish.

* **fine**: point to plane against the whole map (:mod:`.refine`), pairs within two frame voxels; the first
  steps run on a stride of the polish points (``polish.coarse_stride``), the last ones and the Hessian on all;
* **basin**: GICP of the scan against the map's last scan (:mod:`.basin`), pairs within ``polish.wide_distance``
  frame voxels: it finds the basin from a start a metre or tens of degrees off;
* **wide**: the basin, then fine (:meth:`.contest.Contest.enter`, which skips the fine stage when the basin is an
  answer already there).

A polish *converged within reach* of a pose when it stopped before its budget and its answer lies within its
pairing distance of that pose (translation + RMS range x rotation): the pose was already in the basin the polish
settled in, so the two cannot be rival hypotheses.
"""
from __future__ import annotations

import numpy as np

from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.steps.basin import gicp
from cemnet_ros.pipeline.steps.frame import Frame
from cemnet_ros.pipeline.steps.health import disagreement
from cemnet_ros.pipeline.steps.refine import PolishResult, point_to_plane_icp

FINE_DISTANCE = 2.0  # frame voxels: the fine polish's pairing distance, and its reach
FINE_SETTLED = 0.01  # frame voxels: the fine polish ends once a step moves the scan less (far below its noise)
BASIN_SETTLED = 0.1  # frame voxels: the basin stage ends once a step moves less (the fine polish does the rest)


def map_sample(config: AlignerConfig, frame: Frame, target_map: VoxelMap, T_guess: np.ndarray, n: int,
               margin: float = 0.0) -> np.ndarray:
    """``n`` map points within the CEM's radius (+ ``margin`` m) of the guessed sensor position."""
    radius = config.preprocess.cem_radius * frame.scale + margin
    return target_map.sample(n, T_guess[:3, 3], radius, seed=config.draw_seed)


class Polisher:
    """The polishes of one frame against one map; ``effort`` (0, 1] scales their iteration budgets (a live node
    that has fallen behind spends less on each scan)."""

    def __init__(self, config: AlignerConfig, frame: Frame, target_map: VoxelMap, effort: float = 1.0) -> None:
        self.config, self.frame, self.map, self.effort = config, frame, target_map, effort

    @property
    def iters(self) -> int:
        """The fine polish's budget of Gauss-Newton steps."""
        return max(1, round(self.effort * self.config.polish.iters))

    @property
    def reach(self) -> float:
        """The fine polish's pairing distance (m)."""
        return FINE_DISTANCE * self.frame.polish_voxel

    @property
    def reach_rad(self) -> float:
        """The rotation (rad) that moves a point at the RMS range by :attr:`reach`: about the spacing of the fine
        polish's rotational basins."""
        return self.reach / self.frame.length

    def fine(self, T_start: np.ndarray) -> PolishResult:
        """Point to plane from ``T_start`` with every polish point, pairs within :attr:`reach`."""
        return point_to_plane_icp(self.map, self.frame.polish, T_start, self.reach, self.iters,
                                  convergence=FINE_SETTLED * self.frame.polish_voxel,
                                  coarse_stride=self.config.polish.coarse_stride)

    def basin(self, T_start: np.ndarray) -> np.ndarray:
        """GICP from ``T_start`` against the map's last scan (``T_start`` itself when the map keeps none)."""
        cfg = self.config.polish
        if self.map.last_scan is None:
            return T_start
        settled_m = BASIN_SETTLED * self.frame.polish_voxel
        return gicp(self.map.last_scan, self.frame.gicp_cloud(self.map.gicp_voxel), T_start,
                    cfg.wide_distance * self.frame.polish_voxel, max(1, round(self.effort * cfg.wide_iters)),
                    (settled_m, settled_m / self.frame.length))

    def within_reach(self, polish: PolishResult, T_pose: np.ndarray) -> bool:
        """``polish`` converged before its budget, within :attr:`reach` of ``T_pose`` (see the module)."""
        if polish.iterations >= self.iters:
            return False
        moved_m, moved_rad = disagreement(T_pose, polish.T_target_source)
        return moved_m + self.frame.length * moved_rad <= self.reach
