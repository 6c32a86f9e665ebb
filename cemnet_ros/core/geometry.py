"""Rigid-motion helpers shared by the engine, the tools and the ROS layer.

Actions and poses use the reference's Euler convention: angles ``[z, y, x]`` with
``R = Rx(x) @ Ry(y) @ Rz(z)`` (scipy ``Rotation.from_euler('zyx', [z, y, x])``).
"""
from __future__ import annotations

import numpy as np
import torch
from scipy.spatial.transform import Rotation


def euler_to_matrix(angles: torch.Tensor) -> torch.Tensor:
    """(..., 3) angles [z, y, x] in radians -> (..., 3, 3) rotation matrices (differentiable)."""
    z, y, x = angles.unbind(-1)
    cz, sz, cy, sy, cx, sx = z.cos(), z.sin(), y.cos(), y.sin(), x.cos(), x.sin()
    rows = (
        cy * cz, -cy * sz, sy,
        cx * sz + sx * sy * cz, cx * cz - sx * sy * sz, -sx * cy,
        sx * sz - cx * sy * cz, sx * cz + cx * sy * sz, cx * cy,
    )
    return torch.stack(rows, -1).reshape(*angles.shape[:-1], 3, 3)


def matrix_to_euler(rotation: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) rotation matrices -> (..., 3) angles [z, y, x] (inverse of :func:`euler_to_matrix`)."""
    y = torch.asin(rotation[..., 0, 2].clamp(-1.0, 1.0))
    z = torch.atan2(-rotation[..., 0, 1], rotation[..., 0, 0])
    x = torch.atan2(-rotation[..., 1, 2], rotation[..., 2, 2])
    return torch.stack((z, y, x), -1)


def transform_points(points: torch.Tensor, rotation: torch.Tensor, translation: torch.Tensor) -> torch.Tensor:
    """Apply ``R p + t`` to (..., n, 3) points with (..., 3, 3) rotations and (..., 3) translations."""
    return points @ rotation.transpose(-1, -2) + translation.unsqueeze(-2)


def action_to_rt(action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(..., 6) action [z, y, x, tx, ty, tz] -> rotation (..., 3, 3), translation (..., 3)."""
    return euler_to_matrix(action[..., :3]), action[..., 3:]


def euler_to_matrix_np(angles: np.ndarray) -> np.ndarray:
    """NumPy twin of :func:`euler_to_matrix`."""
    return euler_to_matrix(torch.as_tensor(np.asarray(angles, dtype=np.float64))).numpy()


def matrix_to_euler_np(rotation: np.ndarray) -> np.ndarray:
    """NumPy twin of :func:`matrix_to_euler`."""
    return matrix_to_euler(torch.as_tensor(np.asarray(rotation, dtype=np.float64))).numpy()


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


def procrustes(source: torch.Tensor, target: torch.Tensor, weights: torch.Tensor | None = None
               ) -> tuple[torch.Tensor, torch.Tensor]:
    """Batched weighted least-squares rigid fit ``target ~ R source + t`` (Kabsch, reflection-safe).

    source, target: (B, n, 3); weights: (B, n) or None. Returns R (B, 3, 3), t (B, 3).
    """
    if weights is None:
        weights = torch.ones(source.shape[:-1], dtype=source.dtype, device=source.device)
    w = weights / weights.sum(-1, keepdim=True).clamp_min(1e-12)
    src_mean = (w.unsqueeze(-1) * source).sum(-2)
    tgt_mean = (w.unsqueeze(-1) * target).sum(-2)
    cov = (w.unsqueeze(-1) * (source - src_mean.unsqueeze(-2))).transpose(-1, -2) @ (target - tgt_mean.unsqueeze(-2))
    u, _, vh = torch.linalg.svd(cov)
    v = vh.transpose(-1, -2)
    d = torch.det(v @ u.transpose(-1, -2))
    fix = torch.diag_embed(torch.stack([torch.ones_like(d), torch.ones_like(d), d], -1))
    rotation = v @ fix @ u.transpose(-1, -2)
    translation = tgt_mean - (rotation @ src_mean.unsqueeze(-1)).squeeze(-1)
    return rotation, translation


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
