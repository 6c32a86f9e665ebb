"""A street-like point set (sampled surfaces, not ray-cast) and rigid motions, for the pipeline and node tests
(metres): ground, two walls and boxes, so that every pose component is observable."""
from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy.spatial.transform import Rotation


def make_transform(yaw: float = 0.0, t: Sequence[float] = (0.0, 0.0, 0.0), roll: float = 0.0,
                   pitch: float = 0.0) -> np.ndarray:
    """A 4x4 rigid transform from extrinsic x-y-z angles (rad) and a translation."""
    out = np.eye(4)
    out[:3, :3] = Rotation.from_euler("xyz", [roll, pitch, yaw]).as_matrix()
    out[:3, 3] = t
    return out


def make_world(seed: int = 1, n: int = 20000) -> np.ndarray:
    """(~n, 3) points: ground at z = -1.5, two walls and a few boxes: structure in every direction."""
    rng = np.random.default_rng(seed)
    ground = np.c_[rng.uniform(-20, 20, (n // 2, 2)), np.full(n // 2, -1.5)]
    wall_a = np.c_[rng.uniform(-20, 20, n // 8), np.full(n // 8, 6.0), rng.uniform(-1.5, 3, n // 8)]
    wall_b = np.c_[np.full(n // 8, 15.0), rng.uniform(-6, 6, n // 8), rng.uniform(-1.5, 3, n // 8)]
    boxes = [rng.uniform(-0.8, 0.8, (n // 32, 3)) + [c[0], c[1], -0.7] for c in rng.uniform(-12, 12, (8, 2))]
    return np.vstack([ground, wall_a, wall_b] + boxes)


def seen_from(world: np.ndarray, T_world_sensor: np.ndarray) -> np.ndarray:
    """``world`` points (n, 3) in the frame of a sensor at ``T_world_sensor``."""
    return (world - T_world_sensor[:3, 3]) @ T_world_sensor[:3, :3]


def street_scan(world: np.ndarray, T_world_sensor: np.ndarray, rng: np.random.Generator, n: int = 12000
                ) -> np.ndarray:
    """A scan-like random subset of ``n`` of the world's points seen from ``T_world_sensor``, in random order."""
    points = seen_from(world, T_world_sensor)
    return points[rng.permutation(len(points))[:n]]
