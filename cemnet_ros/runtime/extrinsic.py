"""From the sensor's odometry to the robot's (REP-105): the base frame's pose, motion and covariance.

The pipeline estimates ``T_sensor0_sensor``, the sensor's pose in its own first frame. The robot's odom frame is
the base frame at that first scan, so with the extrinsic ``T_base_sensor``::

    T_odom_base = T_base_sensor @ T_sensor0_sensor @ inv(T_base_sensor)

A covariance given about the sensor's position in sensor0 axes (the polish's, :mod:`..steps.covariance`) becomes one
about the base's position in odom axes: rotations turn with R_base_sensor, translations also pick up the
lever arm between the two origins.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def pose_from_xyz_rpy(values: tuple | np.ndarray) -> np.ndarray:
    """4x4 from (x, y, z, roll, pitch, yaw): translation, then R = Rz(yaw) Ry(pitch) Rx(roll) (ROS convention)."""
    x, y, z, roll, pitch, yaw = (float(v) for v in values)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", [roll, pitch, yaw]).as_matrix()
    T[:3, 3] = (x, y, z)
    return T


def pose_msg_to_matrix(pose) -> np.ndarray:
    """A geometry_msgs/Pose (rclpy or rosbags) -> 4x4; the quaternion normalised, a zero one refused (ValueError)."""
    return _matrix(pose.position, pose.orientation)


def transform_msg_to_matrix(transform) -> np.ndarray:
    """A geometry_msgs/Transform (e.g. of a TF lookup) -> 4x4, as :func:`pose_msg_to_matrix`."""
    return _matrix(transform.translation, transform.rotation)


def _matrix(translation, rotation) -> np.ndarray:
    q = np.array([rotation.x, rotation.y, rotation.z, rotation.w], dtype=np.float64)
    norm = np.linalg.norm(q)
    if not np.isfinite(norm) or norm < 1e-9:
        raise ValueError(f"invalid pose quaternion {q.tolist()}")
    out = np.eye(4)
    out[:3, :3] = Rotation.from_quat(q / norm).as_matrix()
    out[:3, 3] = [translation.x, translation.y, translation.z]
    return out


class BaseFrame:
    """Conjugates the sensor's trajectory by a fixed extrinsic ``T_base_sensor`` (4x4)."""

    def __init__(self, T_base_sensor: np.ndarray) -> None:
        self.T_base_sensor = np.asarray(T_base_sensor, dtype=np.float64)
        self._T_sensor_base = np.linalg.inv(self.T_base_sensor)

    def pose(self, T_sensor0_sensor: np.ndarray) -> np.ndarray:
        """T_odom_base."""
        return self.T_base_sensor @ T_sensor0_sensor @ self._T_sensor_base

    def sensor_pose(self, T_odom_base: np.ndarray) -> np.ndarray:
        """The inverse of :meth:`pose`: T_sensor0_sensor of a base pose (e.g. a pose set by the user)."""
        return self._T_sensor_base @ T_odom_base @ self.T_base_sensor

    def relative(self, T_prev_curr_sensor: np.ndarray) -> np.ndarray:
        """The base's motion between two scans, in the previous base frame."""
        return self.T_base_sensor @ T_prev_curr_sensor @ self._T_sensor_base

    def covariance(self, covariance_sensor0: np.ndarray, T_sensor0_sensor: np.ndarray) -> np.ndarray:
        """6x6 ROS-order covariance about the sensor (sensor0 axes) -> about the base (odom axes)."""
        R = self.T_base_sensor[:3, :3]
        sensor_in_odom = (self.T_base_sensor @ T_sensor0_sensor)[:3, 3]
        base_in_odom = self.pose(T_sensor0_sensor)[:3, 3]
        d = sensor_in_odom - base_in_odom
        lever = np.array([[0.0, -d[2], d[1]], [d[2], 0.0, -d[0]], [-d[1], d[0], 0.0]])
        J = np.zeros((6, 6))  # [v_base; w] = J [v_sensor; w_sensor]: rotating about the sensor moves the base
        J[:3, :3], J[:3, 3:], J[3:, 3:] = R, lever @ R, R
        return J @ covariance_sensor0 @ J.T


def in_body_axes(covariance_odom: np.ndarray, T_odom_base: np.ndarray) -> np.ndarray:
    """A ROS-order covariance in odom axes expressed in the base's own axes (a twist's frame)."""
    R = T_odom_base[:3, :3].T
    J = np.zeros((6, 6))
    J[:3, :3], J[3:, 3:] = R, R
    return J @ covariance_odom @ J.T
