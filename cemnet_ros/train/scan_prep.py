"""A scan prepared as the node prepares it, as public functions (training must feed the network what the node does).

They mirror :class:`cemnet_ros.pipeline.aligner.ScanAligner`: :func:`auto_scale` and :func:`voxel_cloud` its
``_preprocess`` up to the voxel cloud (``Frame.dense``), :func:`cem_cloud` the rest of it (``Frame.near`` cut to
``Frame.sampled``), :func:`network_units` its ``_units``. Everything is in metres in the sensor frame until
:func:`network_units`, whose maps put a cloud on the network's unit sphere (epsilon = 0.1).
"""
from __future__ import annotations

import numpy as np

from cemnet_ros.pipeline.config import PreprocessConfig
from cemnet_ros.pipeline.input_checks import ScanRejected
from cemnet_ros.pipeline.preprocess import crop_range, finite_points, robust_radius, subsample, voxel_downsample


def cropped(points: np.ndarray, config: PreprocessConfig) -> np.ndarray:
    """Finite points within the range crop; ScanRejected when fewer than ``min_points`` remain."""
    kept = crop_range(finite_points(points), config.min_range, config.max_range)
    if len(kept) < config.min_points:
        raise ScanRejected(f"too few points: {len(kept)} after range crop, need {config.min_points}",
                           "too_few_points")
    return kept


def auto_scale(points: np.ndarray, config: PreprocessConfig) -> float:
    """Metres per network unit: ``config.scale``, or (0 = auto) the robust radius of this scan after the crop, as
    the node measures it on the scan that starts a trajectory."""
    if config.scale > 0:
        return float(config.scale)
    scale = robust_radius(cropped(points, config))
    if not scale > 0:
        raise ScanRejected("degenerate cloud: all points coincide, cannot measure its scale", "degenerate")
    return scale


def voxel_size(config: PreprocessConfig, scale: float) -> float:
    """The frame voxel (m): ``config.voxel_size``, 0 = auto (scale / 100), negative = none (0)."""
    return max(config.voxel_size if config.voxel_size != 0 else scale / 100.0, 0.0)


def voxel_cloud(points: np.ndarray, config: PreprocessConfig, scale: float) -> np.ndarray:
    """The range-cropped voxel cloud (the aligner's ``Frame.dense``); ScanRejected when too few points."""
    dense = voxel_downsample(cropped(points, config), voxel_size(config, scale))
    if len(dense) < config.min_points:
        raise ScanRejected(f"too few points: {len(dense)} after preprocessing, need {config.min_points}",
                           "too_few_points")
    return dense


def cem_cloud(dense: np.ndarray, config: PreprocessConfig, scale: float, n_points: int, seed: int) -> np.ndarray:
    """At most ``n_points`` of the voxel points within the CEM's radius of the sensor (all of them when fewer
    than ``min_points`` are that close), cut with ``config.sampling``: the aligner's ``Frame.sampled``."""
    near = dense[np.einsum("ij,ij->i", dense, dense) <= (config.cem_radius * scale) ** 2]
    near = near if len(near) >= config.min_points else dense
    return subsample(near, n_points, config.sampling, seed)


def network_units(scale: float, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(to_units, from_units) 4x4 maps between metres and network units centred on ``centre`` (3,) m."""
    to_units = np.eye(4)
    to_units[:3, :3] /= scale
    to_units[:3, 3] = -np.asarray(centre, dtype=np.float64) / scale
    return to_units, np.linalg.inv(to_units)
