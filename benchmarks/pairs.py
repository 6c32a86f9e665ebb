"""Pair sets: two scans and the true motion between them, each pair through a fresh odometry of each method.

``kitti_gaps``: every pair (i, i + g) of the full-resolution KITTI sample scans; ``large_motion``: ray-cast
courtyard pairs, yaw U[-180, 180] deg, |t| U[0, 10] m; ``bag_pairs``: the same kind of motions between the scans
of a bag with ground truth.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from benchmarks.metrics import summarize
from benchmarks.streams import Scan, run_stream, step_record, step_records
from cemnet_ros.data.kitti import kitti_scans
from cemnet_ros.data.scenes import (
    COURTYARD_BOUNDS,
    LidarModel,
    courtyard_scene,
    in_free_space,
    lidar_scan,
    random_sensor_pose,
)
from cemnet_ros.io.console import progress
from cemnet_ros.replay.bag_reader import BagReader, SkippedMessage
from cemnet_ros.train.bag_scans import poses_at


@dataclass
class Pair:
    """Two scans (sensor frames) and the true motion T_1_2 between them; ``gap`` scans apart at 10 Hz."""

    name: str
    first: np.ndarray
    second: np.ndarray
    truth: np.ndarray
    gap: int = 1


def run_pairs(pairs: list[Pair], methods: dict[str, Callable], max_range: float, label: str) -> dict:
    """Each pair through a fresh odometry of each method; the step is the second scan."""
    out = {}
    for name, factory in methods.items():
        steps = [pair_record(pair, run_stream(factory, max_range, [pair.first, pair.second], [0, pair.gap]))
                 for pair in progress(pairs, f"{label} {name}")]
        out[name] = {"summary": summarize(steps), "steps": steps}
    return out


def pair_record(pair: Pair, results: list[Scan]) -> dict:
    """The step record of a pair's second scan; a failed first scan fails the pair."""
    if results[0].pose is None:
        return step_record(pair.name, results[1], None, None, f"first scan: {results[0].error}")
    return step_records(pair.name, results, {0: np.eye(4), pair.gap: pair.truth})[0]


def kitti_pairs(root: Path, max_gap: int) -> list[Pair]:
    """Every pair (i, i + g), g = 1..max_gap, of the full-resolution KITTI sample scans."""
    frames = [(pts.astype(np.float64), pose) for pts, pose in kitti_scans(root)]
    return [Pair(f"{i}-{i + g}", frames[i][0], frames[i + g][0], np.linalg.inv(frames[i][1]) @ frames[i + g][1], g)
            for g in range(1, max_gap + 1) for i in range(len(frames) - g)]


def random_motion(rng: np.random.Generator, max_translation: float = 10.0, max_tilt_deg: float = 2.0) -> np.ndarray:
    """Yaw U[-180, 180] deg, |t| U[0, max] m in a uniform ground-plane direction, roll/pitch U[-2, 2] deg."""
    motion = np.eye(4)
    roll, pitch = rng.uniform(-max_tilt_deg, max_tilt_deg, 2)
    motion[:3, :3] = Rotation.from_euler("zyx", [rng.uniform(-180, 180), pitch, roll], degrees=True).as_matrix()
    heading, distance = rng.uniform(0, 2 * np.pi), rng.uniform(0, max_translation)
    motion[:3, 3] = distance * np.cos(heading), distance * np.sin(heading), 0.0
    return motion


def large_motion_pairs(n: int, seed: int) -> list[Pair]:
    """Courtyard pairs: a random pose, then that pose moved by ``random_motion`` (redrawn until in free space)."""
    rng, scene, lidar = np.random.default_rng(seed), courtyard_scene(), LidarModel()
    pairs = []
    for i in range(n):
        first = random_sensor_pose(COURTYARD_BOUNDS, rng, scene)
        while True:
            motion = random_motion(rng)
            if in_free_space(scene, (first @ motion)[:3, 3], COURTYARD_BOUNDS):
                break
        a = lidar_scan(scene, first, lidar, rng).astype(np.float64)
        b = lidar_scan(scene, first @ motion, lidar, rng).astype(np.float64)
        pairs.append(Pair(f"pair{i}", a, b, motion))
    return pairs


def read_posed_scans(path: Path) -> tuple[list[np.ndarray], np.ndarray]:
    """The scans of a bag (sensor frames, float64) and their ground-truth poses T_world_sensor (n, 4, 4), read once
    for :func:`bag_pairs`; ValueError when a scan has no ground truth."""
    with BagReader(path) as reader:
        scans = [s for s in reader.scans() if not isinstance(s, SkippedMessage)]
        gt_stamps, gt_poses, _ = reader.ground_truth()
    poses = poses_at([s.stamp_ns for s in scans], gt_stamps, gt_poses)
    if poses is None:
        raise ValueError(f"{path}: bag pairs need ground truth at every scan")
    return [s.points.astype(np.float64) for s in scans], poses


def bag_pairs(clouds: list[np.ndarray], poses: np.ndarray, n: int, seed: int, max_translation: float = 10.0
              ) -> list[Pair]:
    """Large motions between real scans (``read_posed_scans``): two scans whose sensors lie at most
    ``max_translation`` m apart (drawn at random), the second turned about its sensor's z axis by a yaw
    U[-180, 180] deg (a sensor frame still: only the heading changes)."""
    rng, positions = np.random.default_rng(seed), poses[:, :3, 3]
    pairs = []
    for k in range(n):
        i = int(rng.integers(len(clouds)))
        near = np.flatnonzero(np.linalg.norm(positions - positions[i], axis=1) <= max_translation)
        j = int(rng.choice(near[near != i])) if len(near) > 1 else i
        spin = np.eye(4)
        spin[:3, :3] = Rotation.from_euler("z", rng.uniform(-180.0, 180.0), degrees=True).as_matrix()
        truth = np.linalg.inv(poses[i]) @ poses[j] @ np.linalg.inv(spin)
        pairs.append(Pair(f"pair{k}:{i}-{j}", clouds[i], clouds[j] @ spin[:3, :3].T, truth))
    return pairs
