"""Rigid-motion helpers (numpy): the package's one home for rotations, transforms and rigid fits.

Shared by the engine, the pipeline, the evaluation, the replay, the tools and the ROS layer. Actions and poses
use the reference's Euler convention: angles ``[z, y, x]`` with ``R = Rx(x) @ Ry(y) @ Rz(z)`` (scipy
``Rotation.from_euler('zyx', [z, y, x])``). A transform ``T_target_source`` (4x4) maps points of the source frame
into the target frame. The differentiable torch twins are in :mod:`.geometry_torch`; this module imports no
torch (the node's start-up reads it).
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
    action = np.asarray(action, dtype=np.float64)
    return rigid_transform(euler_to_matrix_np(action[:3]), action[3:])


def matrix_to_action_np(transform: np.ndarray) -> np.ndarray:
    """4x4 homogeneous transform -> (6,) action [z, y, x, tx, ty, tz]."""
    transform = np.asarray(transform, dtype=np.float64)
    return np.concatenate([matrix_to_euler_np(transform[:3, :3]), transform[:3, 3]])


def rigid_transform(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """4x4 homogeneous transform of a rotation (3, 3) and a translation (3,): ``p -> R p + t``."""
    out = np.eye(4)
    out[:3, :3] = rotation
    out[:3, 3] = translation
    return out


def rotation_angle_rad(rotation: np.ndarray) -> float:
    """Geodesic angle (radians) of one rotation matrix: its distance to the identity.

    The angle between two rotations is that of their difference, e.g. ``rotation_angle_rad(R_gt.T @ R_pred)``.
    """
    cos = (np.trace(np.asarray(rotation, dtype=np.float64)) - 1.0) / 2.0
    return float(np.arccos(np.clip(cos, -1.0, 1.0)))


def rotation_angle_deg(rotation: np.ndarray) -> float:
    """:func:`rotation_angle_rad` in degrees."""
    return float(np.degrees(rotation_angle_rad(rotation)))


def so3_exp(rotvec: np.ndarray) -> np.ndarray:
    """Rotation matrix of a rotation vector (Rodrigues)."""
    return Rotation.from_rotvec(np.asarray(rotvec, dtype=np.float64)).as_matrix()


def so3_log(rotation: np.ndarray) -> np.ndarray:
    """Rotation vector of a rotation matrix."""
    return Rotation.from_matrix(np.asarray(rotation, dtype=np.float64)).as_rotvec()


def apply_transform(T_target_source: np.ndarray, points_source: np.ndarray) -> np.ndarray:
    """(n, 3) points of the source frame expressed in the target frame: R p + t."""
    return points_source @ T_target_source[:3, :3].T + T_target_source[:3, 3]


def procrustes_np(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares ``R, t`` with ``target ~= R source + t`` for matched (n, 3) points (Kabsch, no reflection).

    The numpy twin of ``geometry_torch.procrustes`` without weights. One point pins only the translation; two
    leave the rotation about their axis free (the SVD's minimal-angle answer is returned).
    """
    source, target = np.asarray(source, dtype=np.float64), np.asarray(target, dtype=np.float64)
    if source.shape != target.shape or source.ndim != 2 or source.shape[1] != 3 or len(source) == 0:
        raise ValueError(f"need two (n, 3) arrays of equal shape, got {source.shape} and {target.shape}")
    src_mean, tgt_mean = source.mean(0), target.mean(0)
    cov = (source - src_mean).T @ (target - tgt_mean)
    u, _, vt = np.linalg.svd(cov)
    fix = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T)) or 1.0])
    rotation = vt.T @ fix @ u.T
    return rotation, tgt_mean - rotation @ src_mean
