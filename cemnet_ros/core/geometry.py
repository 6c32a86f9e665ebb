"""Rigid-motion helpers (numpy) shared by the engine, the pipeline, the tools and the ROS layer.

Actions and poses use the reference's Euler convention: angles ``[z, y, x]`` with
``R = Rx(x) @ Ry(y) @ Rz(z)`` (scipy ``Rotation.from_euler('zyx', [z, y, x])``). The differentiable torch
twins are in :mod:`.geometry_torch`; this module imports no torch (the node's start-up reads it).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def euler_to_matrix_np(angles: np.ndarray) -> np.ndarray:
    """(..., 3) angles [z, y, x] in radians -> (..., 3, 3) rotation matrices (twin of ``euler_to_matrix``)."""
    angles = np.asarray(angles, dtype=np.float64)
    z, y, x = angles[..., 0], angles[..., 1], angles[..., 2]
    cz, sz, cy, sy, cx, sx = np.cos(z), np.sin(z), np.cos(y), np.sin(y), np.cos(x), np.sin(x)
    rows = (
        cy * cz, -cy * sz, sy,
        cx * sz + sx * sy * cz, cx * cz - sx * sy * sz, -sx * cy,
        sx * sz - cx * sy * cz, sx * cz + cx * sy * sz, cx * cy,
    )
    return np.stack(rows, -1).reshape(*angles.shape[:-1], 3, 3)


def matrix_to_euler_np(rotation: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices -> (..., 3) angles [z, y, x] (twin of ``matrix_to_euler``)."""
    rotation = np.asarray(rotation, dtype=np.float64)
    y = np.arcsin(np.clip(rotation[..., 0, 2], -1.0, 1.0))
    z = np.arctan2(-rotation[..., 0, 1], rotation[..., 0, 0])
    x = np.arctan2(-rotation[..., 1, 2], rotation[..., 2, 2])
    return np.stack((z, y, x), -1)


def action_to_matrix_np(action: np.ndarray) -> np.ndarray:
    """(6,) action [z, y, x, tx, ty, tz] -> 4x4 homogeneous transform (inverse of :func:`matrix_to_action_np`)."""
    out = np.eye(4)
    out[:3, :3] = euler_to_matrix_np(np.asarray(action, dtype=np.float64)[:3])
    out[:3, 3] = action[3:]
    return out


def matrix_to_action_np(transform: np.ndarray) -> np.ndarray:
    """4x4 homogeneous transform -> (6,) action [z, y, x, tx, ty, tz]."""
    transform = np.asarray(transform, dtype=np.float64)
    return np.concatenate([matrix_to_euler_np(transform[:3, :3]), transform[:3, 3]])


def rotation_angle_deg(rotation_a: np.ndarray, rotation_b: np.ndarray) -> float:
    """Geodesic angle (degrees) between two rotation matrices."""
    return float(np.degrees(rotation_angle_rad(np.asarray(rotation_a).T @ np.asarray(rotation_b))))


def rotation_angle_rad(rotation: np.ndarray) -> float:
    """Geodesic angle (radians) of one rotation matrix: its distance to the identity."""
    cos = (np.trace(np.asarray(rotation, dtype=np.float64)) - 1.0) / 2.0
    return float(np.arccos(np.clip(cos, -1.0, 1.0)))


def so3_exp(rotvec: np.ndarray) -> np.ndarray:
    """Rotation matrix of a rotation vector (Rodrigues)."""
    return Rotation.from_rotvec(np.asarray(rotvec, dtype=np.float64)).as_matrix()


def so3_log(rotation: np.ndarray) -> np.ndarray:
    """Rotation vector of a rotation matrix."""
    return Rotation.from_matrix(np.asarray(rotation, dtype=np.float64)).as_rotvec()


def apply_transform(T_target_source: np.ndarray, points_source: np.ndarray) -> np.ndarray:
    """(n, 3) points of the source frame expressed in the target frame: R p + t."""
    return points_source @ T_target_source[:3, :3].T + T_target_source[:3, 3]
