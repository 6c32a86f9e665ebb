"""What the library benchmark feeds every method: preprocessed scans, map/source steps with their truth, the
polish stages and perturbed starts."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from benchmarks.real import Sequence
from cemnet_ros.core.geometry import rigid_transform, so3_exp
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.pipeline.steps.frame import Frame, Preprocessor

WIDE_POINTS = 1000  # polish points of the timed schedule's wide stage
FINE_DISTANCE_VOXELS = 2.0  # the fine stage's pairing distance, frame voxels (as pipeline/steps/polish.py)
OFFSETS = ((0.3, 3.0), (1.0, 10.0))  # start offsets from the true pose (m, deg), random directions


@dataclass(frozen=True)
class Stage:
    """One point-to-plane polish run: about ``points`` of the polish points, pairs within ``max_distance``."""

    points: int
    max_distance: float  # m
    iters: int

    def subset(self, polish: np.ndarray) -> np.ndarray:
        """Every k-th polish point, about ``points`` of them: the polish points are in scan order, so a stride
        spans the whole scan (a prefix would be a wedge)."""
        return polish[::max(1, len(polish) // self.points)]


def polish_stages(config: AlignerConfig, voxel: float) -> list[Stage]:
    """A two-stage point-to-plane polish from a start that may be a metre or degrees off, the schedule compared
    with the libraries' ICPs: a wide pairing on a subset finds the basin, the fine pairing on every polish point
    brings the precision (the node's own wide stage is small_gicp's GICP, :mod:`cemnet_ros.pipeline.basin`)."""
    return [Stage(WIDE_POINTS, config.polish.wide_distance * voxel, config.polish.wide_iters),
            Stage(config.polish.points, FINE_DISTANCE_VOXELS * voxel, config.polish.iters)]


def sequence_frames(sequence: Sequence, config: AlignerConfig) -> list[Frame]:
    """Every scan through the node's preprocessing at the first scan's scale (adopted, as the node does)."""
    preprocessor = Preprocessor(config)
    first = preprocessor.frame(sequence.scans[0])
    preprocessor.adopt(first)
    return [first] + [preprocessor.frame(points) for points in sequence.scans[1:]]


@dataclass
class Step:
    """Scan ``index`` (the source) against the scans before it (the map), all placed in the frame of the last
    map scan (the target) by the true poses."""

    index: int
    map_scans: list[np.ndarray]  # voxel clouds, each in its sensor frame
    T_target_map_scans: list[np.ndarray]
    dense: np.ndarray  # the source's voxel cloud (sensor frame)
    polish: np.ndarray  # its polish subset
    T_target_source: np.ndarray  # the truth


def polish_steps(frames: list[Frame], poses: list[np.ndarray], map_scans: int, pairs: int) -> list[Step]:
    """Up to ``pairs`` steps k -> k + 1 whose map holds ``map_scans`` scans (k - map_scans + 1 .. k)."""
    steps = []
    for k in range(map_scans - 1, min(map_scans - 1 + pairs, len(frames) - 1)):
        T_world_target = poses[k]
        kept = range(k - map_scans + 1, k + 1)
        steps.append(Step(k + 1, [frames[j].dense for j in kept],
                          [np.linalg.inv(T_world_target) @ poses[j] for j in kept], frames[k + 1].dense,
                          frames[k + 1].polish, np.linalg.inv(T_world_target) @ poses[k + 1]))
    return steps


def orthonormal(T: np.ndarray) -> np.ndarray:
    """``T`` with its rotation made exactly orthonormal (SVD): KISS-ICP's Sophus aborts on KITTI's poses, whose
    rotations are off by ~1e-6."""
    u, _, vt = np.linalg.svd(T[:3, :3])
    return rigid_transform(u @ vt, T[:3, 3])


def perturbed(T_target_source: np.ndarray, metres: float, degrees: float, rng: np.random.Generator) -> np.ndarray:
    """``T_target_source`` moved in the source frame by ``metres`` along and ``degrees`` about random directions."""
    axis, direction = rng.normal(size=3), rng.normal(size=3)
    offset = rigid_transform(so3_exp(np.radians(degrees) * axis / np.linalg.norm(axis)),
                             metres * direction / np.linalg.norm(direction))
    return T_target_source @ offset


def box_scan(n_points: int, seed: int = 0, size: float = 20.0, noise: float = 0.01) -> np.ndarray:
    """(n, 3) points on the floor and four walls of a box around the sensor, with an off-centre pillar (so that
    no motion leaves it unchanged): a small synthetic scan with planes for every piece to work on."""
    rng = np.random.default_rng(seed)
    half = size / 2.0
    uv = rng.uniform(-half, half, (n_points, 2))
    face = rng.integers(0, 6, n_points)
    points = np.empty((n_points, 3))
    points[:, 0], points[:, 1], points[:, 2] = uv[:, 0], uv[:, 1], -2.0  # floor
    for k, (axis, sign) in enumerate([(0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0)], start=1):
        on = face == k
        points[on, axis] = sign * half
        points[on, 1 - axis] = uv[on, 0]
        points[on, 2] = -2.0 + (uv[on, 1] + half) / size * 4.0  # walls 4 m high
    pillar = face == 5
    angle = rng.uniform(0.0, 2.0 * np.pi, int(pillar.sum()))
    points[pillar] = np.c_[3.0 + 0.5 * np.cos(angle), 2.0 + 0.5 * np.sin(angle),
                           -2.0 + (uv[pillar, 1] + half) / size * 4.0]
    return points + rng.normal(0.0, noise, points.shape)
