"""Two point clouds, one transform: the scan pipeline's pair mode for metric scans, the paper's engine for objects.

The engine (:func:`cemnet_ros.core.register`) works in the units of the ModelNet unit sphere: object-scale clouds
and the paper's protocol. On LiDAR scans in metres it lands centimetres off (KITTI scans 0-1 and 3-4: 6 and
11 cm); the scan pipeline's pair mode
(:meth:`~cemnet_ros.pipeline.aligner.ScanAligner.align_pair`: the global CEM search, a point-to-plane polish
in metres, the step judged) lands within 2 cm there. ``mode="auto"`` picks by size (:func:`chosen_method`).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Optional

import numpy as np

from cemnet_ros.core.config import RegistrationConfig
from cemnet_ros.pipeline.config import AlignerConfig

MODES = ("auto", "scan", "engine")
METRIC_EXTENT = 5.0  # auto: a cloud whose bounding box is longer than this on a side is a metric scan
UNIT_RADIUS = 2.0  # the engine: clouds smaller than this (max distance to the centroid) are in network units


@dataclass
class CloudAlignment:
    """``transform`` maps the source onto the target (``target ~= R @ source + t``, the clouds' units)."""

    transform: np.ndarray  # (4, 4)
    method: str  # "scan" (the scan pipeline's pair mode) or "engine"
    fitness: float  # scan: inlier share after the polish; engine: max-consensus inlier share at epsilon
    accepted: bool  # scan: the pipeline's judge vouches for it; engine: always (it has no judge)
    scale: float  # units per network unit
    runtime_s: float
    sigma: Optional[np.ndarray] = None  # engine: the CEM's final spread [euler z, y, x (rad), tx, ty, tz (units)]
    reason: str = ""  # scan: why the judge flagged it, if it did


def chosen_method(source: np.ndarray, target: np.ndarray, mode: str = "auto") -> str:
    """``"scan"`` or ``"engine"``: ``mode`` itself, or for ``"auto"`` the scan pipeline when either cloud's
    bounding box is longer than :data:`METRIC_EXTENT` on a side (metric scans), else the engine."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, not {mode!r}")
    if mode != "auto":
        return mode
    extent = max(float(np.ptp(cloud, axis=0).max()) for cloud in (source, target))
    return "scan" if extent > METRIC_EXTENT else "engine"


def engine_scale(source: np.ndarray, target: np.ndarray) -> float:
    """Units per network unit for the engine: 1 when both clouds have a radius (max distance to their centroid)
    below :data:`UNIT_RADIUS`, else the 90th percentile of the target's distances to its centroid."""
    radius = max(np.linalg.norm(c - c.mean(0), axis=1).max() for c in (source, target))
    if radius < UNIT_RADIUS:
        return 1.0
    return float(np.percentile(np.linalg.norm(target - target.mean(0), axis=1), 90))


def align_clouds(source: np.ndarray, target: np.ndarray, mode: str = "auto", *,
                 registration: Optional[RegistrationConfig] = None, pipeline: Optional[AlignerConfig] = None,
                 scale: Optional[float] = None) -> CloudAlignment:
    """Align (n, 3) ``source`` onto (m, 3) ``target`` with the method :func:`chosen_method` picks.

    ``registration`` configures the engine, ``pipeline`` the scan pipeline (defaults: the package's);
    ``scale`` (units per network unit) replaces the automatic one of either.
    """
    source, target = np.asarray(source, dtype=np.float64), np.asarray(target, dtype=np.float64)
    if chosen_method(source, target, mode) == "scan":
        return _pair_mode(source, target, pipeline or AlignerConfig(), scale)
    return _engine(source, target, registration or RegistrationConfig(), scale)


def _pair_mode(source: np.ndarray, target: np.ndarray, config: AlignerConfig,
               scale: Optional[float]) -> CloudAlignment:
    from cemnet_ros.pipeline.aligner import ScanAligner  # loads torch and the kernels: only when used

    if scale is not None:
        config = dataclasses.replace(config, preprocess=dataclasses.replace(config.preprocess, scale=scale))
    aligner = ScanAligner(config)
    step = aligner.align_pair(source, target, 0)
    return CloudAlignment(step.pose, "scan", float(step.fitness), bool(step.accepted), float(aligner.scale or 0.0),
                          float(step.latency_s), reason=step.reason)


def _engine(source: np.ndarray, target: np.ndarray, config: RegistrationConfig,
            scale: Optional[float]) -> CloudAlignment:
    from cemnet_ros.core import register

    scale = engine_scale(source, target) if scale is None else scale
    result = register(source / scale, target / scale, config)
    transform, sigma = result.transform.copy(), result.sigma.copy()
    transform[:3, 3] *= scale
    sigma[3:] *= scale
    return CloudAlignment(transform, "engine", float(result.fitness), True, scale, float(result.runtime_s), sigma)
