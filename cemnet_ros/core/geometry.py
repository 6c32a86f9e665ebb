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

SMALL_ANGLE = 1e-4  # rad: below this the SE(3) exponential's coefficients use their Taylor series


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


def turned_in_place(T_pose: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """A copy of the 4x4 ``T_pose`` rotated about its own origin and axes by the angles [z, y, x] (rad)."""
    out = np.array(T_pose, dtype=np.float64)
    out[:3, :3] = out[:3, :3] @ euler_to_matrix_np(angles)
    return out


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


def se3_log(transform: np.ndarray) -> np.ndarray:
    """Twist (6,) [rho, omega] of a rigid transform, ``transform = exp(twist^)`` (closed form).

    Not scipy's ``logm``: with a multithreaded BLAS on a busy machine one call can take tens of milliseconds.
    """
    T = np.asarray(transform, dtype=np.float64)
    omega = so3_log(T[:3, :3])
    theta = float(np.linalg.norm(omega))
    W = hat(omega)
    if theta < 1e-2:  # the closed form cancels as 1 / theta^2: its Taylor series is exact to 1e-18 here
        c = 1.0 / 12.0 + theta ** 2 / 720.0 + theta ** 4 / 30240.0
    else:
        c = (1.0 - theta * np.sin(theta) / (2.0 * (1.0 - np.cos(theta)))) / (theta * theta)
    rho = (np.eye(3) - 0.5 * W + c * (W @ W)) @ T[:3, 3]  # V(omega)^-1 t
    return np.r_[rho, omega]


def se3_exp(twist: np.ndarray) -> np.ndarray:
    """4x4 rigid transform exp(twist^) of a twist (6,) [rho, omega] (closed form; inverse of :func:`se3_log`)."""
    xi = np.asarray(twist, dtype=np.float64)
    W = hat(xi[3:])
    a, b, c = (float(k[0]) for k in exp_coefficients(np.array([np.linalg.norm(xi[3:])])))
    out = np.eye(4)
    out[:3, :3] = np.eye(3) + a * W + b * (W @ W)
    out[:3, 3] = (np.eye(3) + b * W + c * (W @ W)) @ xi[:3]
    return out


def hat(w: np.ndarray) -> np.ndarray:
    """The 3x3 skew matrix [w]x of a vector (3,): hat(w) @ v = w x v."""
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def exp_coefficients(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """sin(x)/x, (1 - cos x)/x^2, (x - sin x)/x^3 of the SE(3) exponential (Taylor series near 0)."""
    small = theta < SMALL_ANGLE
    x = np.where(small, 1.0, theta)
    x2 = theta * theta
    a = np.where(small, 1.0 - x2 / 6.0, np.sin(x) / x)
    b = np.where(small, 0.5 - x2 / 24.0, (1.0 - np.cos(x)) / (x * x))
    c = np.where(small, 1.0 / 6.0 - x2 / 120.0, (x - np.sin(x)) / (x * x * x))
    return a, b, c
