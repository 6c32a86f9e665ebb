"""Scans made into frames in the trajectory's units (step 1 of the recipe in :mod:`..aligner`).

Units: the network and the CEM's epsilon live on the ModelNet unit sphere. A trajectory's ``scale`` (metres per
network unit) is fixed by configuration or, in auto mode, by the robust radius of the scan that starts it; the
frame voxel follows from it. A scan is adopted as the measure only once it is used: a rejected or implausible
scan must not fix the units of the trajectory.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Optional

import numpy as np

from cemnet_ros.pipeline.config import AlignerConfig, PreprocessConfig
from cemnet_ros.pipeline.errors import ScanRejected
from cemnet_ros.pipeline.map.gicp_cloud import GicpCloud, gicp_cloud
from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.steps.preprocess import finite_in_range, robust_radius, subsample, voxel_downsample_in_range

LOST_RESCALE_RATIO = 2.0  # a lost trajectory measures the auto scale again on a scan this much larger or smaller


@dataclass
class Frame:
    """A preprocessed scan (sensor frame, metres): voxel cloud (map), polish subset and CEM subset.

    The CEM sees points near the sensor only: its look-up lattices span the clouds' box, and far points make
    that box (and its cache misses) large for little information.
    """

    dense: np.ndarray
    polish: np.ndarray
    sampled: np.ndarray
    near: np.ndarray  # the voxel points within the CEM's radius (the global search draws from them)
    scale: float  # metres per network unit this frame was prepared with
    voxel: float  # its voxel size (m); 0 = no voxel grid
    _gicp: dict[float, GicpCloud] = field(default_factory=dict, repr=False, compare=False)

    def gicp_cloud(self, voxel: float) -> GicpCloud:
        """The voxel cloud thinned to ``voxel`` with covariances, for the polish's wide stage (:mod:`.basin`);
        made once per voxel size."""
        if voxel not in self._gicp:
            self._gicp[voxel] = gicp_cloud(self.dense, voxel)
        return self._gicp[voxel]

    @cached_property
    def length(self) -> float:
        """RMS range of the polish points: the lever arm that makes rotations comparable to translations."""
        return float(np.sqrt(np.mean(np.sum(self.polish ** 2, axis=1)))) or 1.0

    @property
    def polish_voxel(self) -> float:
        """The unit of the polish's pairing distances (m): the voxel, or scale / 100 without a voxel grid."""
        return polish_voxel(self.voxel, self.scale)

    def network_units(self, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(to_units, from_units) at this frame's scale, centred on ``centre`` (3,) m."""
        return network_units(self.scale, centre)


def cropped(points: np.ndarray, config: PreprocessConfig) -> np.ndarray:
    """Finite points within the range crop (m, sensor frame); ScanRejected when fewer than ``min_points`` remain."""
    kept = finite_in_range(points, config.min_range, config.max_range)
    if len(kept) < config.min_points:
        raise ScanRejected(f"too few points: {len(kept)} after range crop, need {config.min_points}",
                           "too_few_points")
    return kept


def measured_scale(points_cropped: np.ndarray) -> float:
    """The auto scale (metres per network unit) of a cropped scan: its robust radius."""
    scale = robust_radius(points_cropped)
    if not scale > 0:
        raise ScanRejected("degenerate cloud: all points coincide, cannot measure its scale", "degenerate")
    return scale


def voxel_size(config: PreprocessConfig, scale: float) -> float:
    """The frame voxel (m): ``config.voxel_size``, 0 = auto (scale / 100), negative = no voxel grid (0)."""
    return max(config.voxel_size if config.voxel_size != 0 else scale / 100.0, 0.0)


def polish_voxel(voxel: float, scale: float) -> float:
    """The unit of the polish's pairing distances and of the map's voxels (m): the frame voxel, or scale / 100
    without a voxel grid."""
    return voxel if voxel > 0 else scale / 100.0


def voxel_cloud(points: np.ndarray, config: PreprocessConfig, voxel: float) -> np.ndarray:
    """The voxel cloud of a scan's finite points within the range crop (the map's points, :attr:`Frame.dense`);
    ScanRejected when too few are in range or remain."""
    dense, n_in_range = voxel_downsample_in_range(points, voxel, config.min_range, config.max_range)
    if n_in_range < config.min_points:
        raise ScanRejected(f"too few points: {n_in_range} after range crop, need {config.min_points}",
                           "too_few_points")
    if len(dense) < config.min_points:
        raise ScanRejected(f"too few points: {len(dense)} after preprocessing, need {config.min_points}",
                           "too_few_points")
    return dense


def near_points(dense: np.ndarray, config: PreprocessConfig, scale: float) -> np.ndarray:
    """The voxel points within the CEM's radius of the sensor (all of them when fewer than ``min_points`` are)."""
    near = dense[np.einsum("ij,ij->i", dense, dense) <= (config.cem_radius * scale) ** 2]
    return near if len(near) >= config.min_points else dense


def network_units(scale: float, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(to_units, from_units): 4x4 maps between metres and network units centred on ``centre`` (3,) m."""
    to_units = np.eye(4)
    to_units[:3, :3] /= scale
    to_units[:3, 3] = -np.asarray(centre) / scale
    return to_units, np.linalg.inv(to_units)


class Preprocessor:
    """Scans -> :class:`Frame` at the trajectory's scale, which it holds (auto: measured, then adopted)."""

    def __init__(self, config: AlignerConfig) -> None:
        self.config = config
        self._fixed_scale = config.preprocess.scale if config.preprocess.scale > 0 else None
        self.reset()

    def reset(self) -> None:
        """Forget an auto scale: the next adopted frame measures it again."""
        self.scale: Optional[float] = self._fixed_scale
        self.voxel = 0.0

    def frame(self, points: np.ndarray, scale: Optional[float] = None) -> Frame:
        """Metres, cropped and voxelised at ``scale`` (default: the trajectory's; auto: this scan's robust radius).

        Raises ScanRejected.
        """
        cfg = self.config.preprocess
        scale = self.scale if scale is None else scale
        if scale is None:
            scale = measured_scale(cropped(points, cfg))
        voxel = voxel_size(cfg, scale)
        dense = voxel_cloud(points, cfg, voxel)
        near = near_points(dense, cfg, scale)
        seed = self.config.draw_seed
        return Frame(dense, subsample(dense, self.config.polish.points, "random", seed),
                     subsample(near, self.config.registration.n_points, cfg.sampling, seed), near, scale, voxel)

    def adopt(self, frame: Frame) -> None:
        """The frame's units become the trajectory's (the first scan of a trajectory, a pair target)."""
        self.scale, self.voxel = frame.scale, frame.voxel

    def rescaled_if_lost(self, frame: Frame) -> Frame:
        """Auto scale: a restart after being lost measures the scale again when this scan's differs by more than
        ``LOST_RESCALE_RATIO`` (the trajectory may have started from a scan that was not representative)."""
        if self._fixed_scale is not None or self.scale is None:
            return frame
        radius = robust_radius(frame.dense)
        if not self.scale / LOST_RESCALE_RATIO <= radius <= LOST_RESCALE_RATIO * self.scale:
            try:
                frame = self.frame(frame.dense, scale=radius)
            except ScanRejected:
                return frame
            self.adopt(frame)
        return frame

    def new_map(self) -> VoxelMap:
        """An empty local map for frames of the adopted units."""
        if self.scale is None:
            raise RuntimeError("no scale adopted yet: a map needs the trajectory's units")
        voxel = polish_voxel(self.voxel, self.scale)
        max_range = self.config.preprocess.max_range
        return VoxelMap(voxel * self.config.map.voxel_factor, self.config.map.points_per_voxel,
                        max_range if max_range > 0 else 10.0 * self.scale)
