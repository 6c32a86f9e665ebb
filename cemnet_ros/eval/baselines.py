"""Classical baselines for the evaluation: point-to-point ICP and FPFH + RANSAC (+ ICP) via Open3D.

Both return ``(R, t)`` with ``target ~= R @ source + t``. The ICP is the package's one point-to-point ICP
(:mod:`cemnet_ros.core.icp`, also the registration's optional refinement). Open3D is an optional extra
(``pip install open3d-cpu``; on Debian it also needs ``apt-get install libusb-1.0-0``): without it
:func:`fpfh_ransac` raises :class:`BaselineUnavailable` with that advice.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np

from cemnet_ros.core.icp import point_to_point_icp


class BaselineUnavailable(RuntimeError):
    """A baseline's optional dependency is missing."""


@dataclass
class ICPConfig:
    """Point-to-point ICP from an initial guess (identity by default)."""

    max_iterations: int = 50
    tolerance: float = 1e-6  # stop when the mean correspondence distance improves by less than this
    max_distance: Optional[float] = None  # ignore correspondences farther than this (None = keep all)


@dataclass
class FPFHConfig:
    """FPFH + RANSAC + ICP refinement, scaled to unit-sphere objects."""

    voxel_size: float = 0.05
    normal_radius: float = 0.1
    feature_radius: float = 0.25
    ransac_distance: float = 0.075
    ransac_iterations: int = 100_000
    ransac_confidence: float = 0.999
    icp_distance: float = 0.05  # max correspondence distance of the point-to-point refinement
    icp_iterations: int = 50
    seed: int = 0


def _as_points(points: np.ndarray, name: str) -> np.ndarray:
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"{name} must be (n, 3), got {points.shape}")
    if len(points) < 3:
        raise ValueError(f"{name} needs >= 3 points, got {len(points)}")
    if not np.isfinite(points).all():
        raise ValueError(f"{name} has non-finite coordinates")
    return points


def icp(source: np.ndarray, target: np.ndarray, config: Optional[ICPConfig] = None,
        init: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray]:
    """Point-to-point ICP from ``init`` (4x4, default identity): :func:`cemnet_ros.core.icp.point_to_point_icp`."""
    config = config or ICPConfig()
    source, target = _as_points(source, "source"), _as_points(target, "target")
    rotation, translation = np.eye(3), np.zeros(3)
    if init is not None:
        init = np.asarray(init, dtype=np.float64)
        rotation, translation = init[:3, :3].copy(), init[:3, 3].copy()
    return point_to_point_icp(source, target, rotation, translation, config.max_iterations, config.max_distance,
                              config.tolerance)


def open3d_available() -> bool:
    """True when ``import open3d`` works."""
    try:
        import open3d  # noqa: F401
    except Exception:  # noqa: BLE001 - ImportError, or OSError from a missing shared library (libusb)
        return False
    return True


def _import_open3d():
    try:
        import open3d as o3d
    except Exception as exc:  # noqa: BLE001 - as in open3d_available
        raise BaselineUnavailable(
            f"the FPFH+RANSAC baseline needs Open3D, which cannot be imported ({exc}); install it with "
            "'pip install open3d-cpu' (Debian also needs 'apt-get install libusb-1.0-0')") from None
    return o3d


def fpfh_ransac(source: np.ndarray, target: np.ndarray, config: Optional[FPFHConfig] = None
                ) -> Tuple[np.ndarray, np.ndarray]:
    """Global registration: FPFH features on voxel-downsampled clouds, RANSAC, then ICP on the full clouds."""
    o3d = _import_open3d()
    config = config or FPFHConfig()
    source, target = _as_points(source, "source"), _as_points(target, "target")
    reg = o3d.pipelines.registration
    o3d.utility.random.seed(config.seed)

    def features(pcd):
        down = pcd.voxel_down_sample(config.voxel_size)
        down.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=config.normal_radius, max_nn=30))
        fpfh = reg.compute_fpfh_feature(
            down, o3d.geometry.KDTreeSearchParamHybrid(radius=config.feature_radius, max_nn=100))
        return down, fpfh

    src_full, tgt_full = (o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p)) for p in (source, target))
    (src_down, src_fpfh), (tgt_down, tgt_fpfh) = features(src_full), features(tgt_full)
    ransac = reg.registration_ransac_based_on_feature_matching(
        src_down, tgt_down, src_fpfh, tgt_fpfh, True, config.ransac_distance,
        reg.TransformationEstimationPointToPoint(False), 3,
        [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
         reg.CorrespondenceCheckerBasedOnDistance(config.ransac_distance)],
        reg.RANSACConvergenceCriteria(config.ransac_iterations, config.ransac_confidence))
    refined = reg.registration_icp(
        src_full, tgt_full, config.icp_distance, ransac.transformation,
        reg.TransformationEstimationPointToPoint(False),
        reg.ICPConvergenceCriteria(max_iteration=config.icp_iterations))
    transform = np.asarray(refined.transformation, dtype=np.float64)
    return transform[:3, :3].copy(), transform[:3, 3].copy()
