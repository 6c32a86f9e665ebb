"""The numbers that align_node publishes for one pipeline step, in pure numpy (no rclpy, no rosbags).

``align_node`` (live) and ``cemnet-replay`` (offline) both call :func:`odometry_output`, then only fill their
own message types with the result, so a replayed bag carries exactly what the node would have published:

- ``T_odom_base``: the base frame's pose in odom (:class:`~.extrinsic.BaseFrame` conjugates the sensor's);
- ``relative``: the base's motion since the previous step, in the previous base frame (None for the first step
  or after a map restart);
- ``linear``, ``angular``: the twist in the base frame (REP-105): ``t(relative) / dt`` and
  ``rotvec(R(relative)) / dt``; zero while it is unknown;
- ``pose_covariance``: 6x6, ROS order (x, y, z, roll, pitch, yaw), about the base in odom axes: the step's from
  the polishes (``covariance_mode`` registration: this scan's and the previous one's, docs/covariance.md) or the
  fixed variances (inflated on a flagged step);
- ``twist_covariance``: the pose covariance in the axes of the twist (the previous base frame's) over ``dt^2``:
  the spread of the twist that the pose's error gives; ``UNKNOWN_VARIANCE`` on the
  diagonal while the twist is unknown (first step, restart, no ``dt``): huge, never zero;
- :func:`aligned_points`: the scan in odom, for the aligned cloud;
- :func:`tf_parent_child`: the /tf transform's frames and direction.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

import numpy as np
from scipy.spatial.transform import Rotation

from cemnet_ros.core.geometry import apply_transform
from cemnet_ros.runtime.extrinsic import BaseFrame, in_body_axes

UNKNOWN_VARIANCE = 1e6  # a twist nobody measured yet (the first scan): huge, never zero


@dataclass
class OdometryOutput:
    """What one step publishes: base pose, base motion, twist and covariances (ROS order)."""

    T_odom_base: np.ndarray  # (4, 4)
    relative: Optional[np.ndarray]  # (4, 4) T_prev_curr of the base; None for the first step / after a restart
    linear: np.ndarray  # (3,) m/s in the base frame; zeros while unknown
    angular: np.ndarray  # (3,) rad/s in the base frame; zeros while unknown
    pose_covariance: np.ndarray  # (6, 6) about the base, odom axes
    twist_covariance: np.ndarray  # (6, 6) base axes; UNKNOWN_VARIANCE * I while unknown
    twist_known: bool  # a motion and a dt were there to measure it


def covariances(step: Any, base: BaseFrame, T_odom_base: np.ndarray, dt_s: Optional[float], cfg: Any,
                covariance_inflation: float) -> tuple[np.ndarray, np.ndarray]:
    """(pose covariance, twist covariance), ROS order, about the base (docs/node.md).

    ``cfg``: a NodeConfig (covariance_mode, fixed_position_variance, fixed_orientation_variance);
    ``covariance_inflation``: ``health.covariance_inflation`` of the pipeline, applied to fixed variances on a
    flagged step. The twist covariance returned here is the pose covariance in the previous base frame's axes
    (those of the twist) over ``dt^2`` (the pose covariance when there is no ``dt``); :func:`odometry_output`
    replaces it by the unknown one when no motion is known.
    """
    if cfg.covariance_mode == "fixed":
        pose = np.diag([cfg.fixed_position_variance] * 3 + [cfg.fixed_orientation_variance] * 3)
        if not step.accepted:
            pose = pose * covariance_inflation
    else:
        pose = base.covariance(step.covariance, step.pose)
    # the twist is the step's motion over dt in the previous base frame's axes (relative = inv(T_prev) T_curr)
    relative = None if step.relative is None else base.relative(step.relative)
    T_odom_previous = T_odom_base if relative is None else T_odom_base @ np.linalg.inv(relative)
    twist = in_body_axes(pose, T_odom_previous) / dt_s ** 2 if dt_s else pose
    return pose, twist


def odometry_output(step: Any, base: BaseFrame, dt_s: Optional[float], cfg: Any,
                    covariance_inflation: float) -> OdometryOutput:
    """Everything the odometry, pose and TF outputs of one ``AlignmentStep`` carry.

    ``dt_s``: seconds since the previous processed step (None for the first). ``cfg``: a NodeConfig.
    """
    T_odom_base = base.pose(step.pose)
    relative = None if step.relative is None else base.relative(step.relative)
    pose_cov, twist_cov = covariances(step, base, T_odom_base, dt_s, cfg, covariance_inflation)
    known = relative is not None and bool(dt_s)
    if relative is not None and dt_s:
        linear = relative[:3, 3] / dt_s
        angular = Rotation.from_matrix(relative[:3, :3]).as_rotvec() / dt_s
    else:
        linear, angular = np.zeros(3), np.zeros(3)
        twist_cov = np.eye(6) * UNKNOWN_VARIANCE
    return OdometryOutput(T_odom_base, relative, linear, angular, pose_cov, twist_cov, known)


def aligned_points(points_sensor: np.ndarray, T_odom_sensor: np.ndarray, voxel: float) -> np.ndarray:
    """A scan's points in odom for the aligned cloud output, thinned to one per ``voxel`` (m) when > 0."""
    points_odom = apply_transform(T_odom_sensor, points_sensor)
    if voxel <= 0:
        return points_odom
    from cemnet_ros.pipeline.steps.preprocess import voxel_downsample  # numba: not at the node's start-up

    return voxel_downsample(points_odom, voxel)


def tf_parent_child(odom_frame: str, base_frame: str, T_odom_base: np.ndarray, invert: bool
                    ) -> tuple[str, str, np.ndarray]:
    """(parent, child, transform) of the /tf message: odom -> base, or base -> odom with ``invert`` (``invert_tf``:
    for a TF tree whose base frame has a parent already)."""
    if invert:
        return base_frame, odom_frame, np.linalg.inv(T_odom_base)
    return odom_frame, base_frame, T_odom_base
