"""Skewed synthetic LiDAR sequences: every azimuth column ray-cast from the pose at its own time in the sweep.

A real spinning LiDAR takes its sweep (0.1 s at 10 Hz) while moving; at 15 m/s the first and last columns are
1.5 m apart and the scan is distorted (skewed). :func:`skewed_sequence` reproduces that with
:mod:`cemnet_ros.data.scenes`' ray caster along a continuous trajectory, and returns the per-point times that a
driver would put in the cloud (s, relative to the stamp) and the true poses at the stamps: the ground truth for
deskewing (:mod:`cemnet_ros.pipeline.steps.deskew`).

The default drive is a constant body twist (15 m/s forward, 30 deg/s yaw: a circle of 28.6 m radius, too wide
for the courtyard) with small height, roll and pitch oscillations, in :func:`plaza_scene`, a 120 m walled square
whose obstacles keep clear of the circle.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np
from scipy.spatial.transform import Rotation

from cemnet_ros.data.scenes import Box, Cylinder, LidarModel, Scene, raycast

PERIOD_S = 0.1  # 10 Hz: one sweep per scan
SPEED = 15.0  # m/s forward
YAW_RATE_DEG = 30.0  # deg/s
PLAZA_HALF = 60.0  # m: half side of the plaza's walls
LANE = 4.0  # m: obstacles keep at least this far from the driven circle


@dataclass
class SkewedSequence:
    """Scans as a moving sensor delivers them, with per-point times and the true poses at the stamps."""

    scans: list[np.ndarray]  # (n_k, 3) float32: each point in the sensor frame at its own time
    times: list[np.ndarray]  # (n_k,) float64: each point's time, s relative to its scan's stamp
    poses: list[np.ndarray]  # (4, 4) true T_world_sensor at each stamp
    stamps_ns: list[int]
    info: dict = field(default_factory=dict)


def _yawed_box(x: float, y: float, half: tuple[float, float, float], yaw: float) -> Box:
    return Box(np.array([x, y, half[2]]), np.array(half, dtype=float), Rotation.from_euler("z", yaw).as_matrix())


def plaza_scene(seed: int = 0, lane_radius: float = SPEED / np.radians(YAW_RATE_DEG)) -> Scene:
    """A 120 m walled square with buildings, crates, a ramp and poles, none within ``LANE`` m of the circle of
    radius ``lane_radius`` around the origin (the drive's); the layout inside is drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    h, t, wall_h = PLAZA_HALF, 0.4, 8.0
    boxes = [_yawed_box(0.0, -h, (h, t, wall_h / 2), 0.0), _yawed_box(0.0, h, (h, t, wall_h / 2), 0.0),
             _yawed_box(-h, 0.0, (t, h, wall_h / 2), 0.0), _yawed_box(h, 0.0, (t, h, wall_h / 2), 0.0)]
    cylinders = []

    def place(half_xy: float, r_min: float, r_max: float) -> tuple[float, float]:
        """A centre whose footprint (circumradius ``half_xy``) stays clear of the lane."""
        while True:
            r, a = rng.uniform(r_min, r_max), rng.uniform(0.0, 2 * np.pi)
            if abs(r - lane_radius) > half_xy + LANE:
                return r * np.cos(a), r * np.sin(a)

    for _ in range(8):  # buildings: outside the circle, between it and the walls
        half = (rng.uniform(3.0, 7.0), rng.uniform(3.0, 7.0), rng.uniform(2.0, 6.0))
        x, y = place(np.hypot(*half[:2]), lane_radius + 8.0, h - 9.0)
        boxes.append(_yawed_box(x, y, half, rng.uniform(0, np.pi)))
    for _ in range(3):  # a central block
        half = (rng.uniform(2.0, 5.0), rng.uniform(2.0, 5.0), rng.uniform(1.5, 5.0))
        x, y = place(np.hypot(*half[:2]), 0.0, 10.0)
        boxes.append(_yawed_box(x, y, half, rng.uniform(0, np.pi)))
    for _ in range(14):  # crates on both sides of the lane
        half = (rng.uniform(0.4, 1.5), rng.uniform(0.4, 1.5), rng.uniform(0.3, 1.2))
        x, y = place(np.hypot(*half[:2]), 5.0, h - 3.0)
        boxes.append(_yawed_box(x, y, half, rng.uniform(0, np.pi)))
    ramp_x, ramp_y = place(4.5, lane_radius + 6.0, h - 8.0)  # a tilted panel: an oblique normal
    boxes.append(Box(np.array([ramp_x, ramp_y, 1.0]), np.array([4.0, 1.5, 0.15]),
                     Rotation.from_euler("zy", [rng.uniform(0, np.pi), np.radians(-12.0)]).as_matrix()))
    for _ in range(10):  # poles
        radius = rng.uniform(0.15, 0.5)
        x, y = place(radius, 3.0, h - 2.0)
        cylinders.append(Cylinder(x, y, radius, 0.0, rng.uniform(2.5, 6.0)))
    return Scene(boxes, cylinders)


def circle_poses(times: np.ndarray, phase: float, direction: float, speed: float = SPEED,
                 yaw_rate: float = np.radians(YAW_RATE_DEG), oscillation: float = 1.0) -> np.ndarray:
    """(k, 4, 4) T_world_sensor at ``times`` (s): a circle around the origin at constant speed and yaw rate
    (``direction`` +1 left, -1 right) with small height / roll / pitch oscillations (x ``oscillation``)."""
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    radius = speed / yaw_rate
    angle = phase + direction * yaw_rate * t  # position angle around the centre
    heading = angle + direction * np.pi / 2
    roll = oscillation * 0.01 * np.sin(2 * np.pi * 0.3 * t + phase)
    pitch = oscillation * 0.01 * np.sin(2 * np.pi * 0.4 * t + 2 * phase)
    poses = np.tile(np.eye(4), (len(t), 1, 1))
    poses[:, :3, :3] = Rotation.from_euler("zyx", np.c_[heading, pitch, roll]).as_matrix()
    poses[:, :3, 3] = np.c_[radius * np.cos(angle), radius * np.sin(angle),
                            1.8 + oscillation * 0.05 * np.sin(2 * np.pi * 0.5 * t + phase)]
    return poses


def skewed_scan(scene: Scene, column_poses: np.ndarray, lidar: LidarModel, rng: np.random.Generator
                ) -> tuple[np.ndarray, np.ndarray]:
    """One sweep: azimuth column j ray-cast from ``column_poses[j]`` (T_world_sensor at its time).

    Returns (points (n, 3) float32 in each column's own sensor frame, column index (n,) of every point).
    """
    dirs = lidar.directions().reshape(lidar.n_beams, lidar.n_azimuth, 3)
    points, columns = [], []
    for j, pose in enumerate(column_poses):
        ranges = raycast(scene, pose[:3, 3], dirs[:, j] @ pose[:3, :3].T, lidar.max_range)
        keep = np.isfinite(ranges) & (ranges >= lidar.min_range)
        noisy = ranges[keep] + rng.normal(0.0, lidar.range_noise, keep.sum())
        points.append(dirs[keep, j] * noisy[:, None])
        columns.append(np.full(keep.sum(), j))
    return np.concatenate(points).astype(np.float32), np.concatenate(columns)


def skewed_sequence(n_scans: int, seed: int = 0, lidar: Optional[LidarModel] = None, speed: float = SPEED,
                    yaw_rate_deg: float = YAW_RATE_DEG, period: float = PERIOD_S, stamp_at: float = 0.0,
                    skew: bool = True, scene: Optional[Scene] = None, progress=None) -> SkewedSequence:
    """``n_scans`` scans at 1 / ``period`` Hz of a drive around :func:`plaza_scene` (``seed``: layout, start
    and turn direction), every azimuth column taken at its own time in the sweep.

    Column j of scan k is measured at ``k * period + (j / n_azimuth - stamp_at) * period``: the stamp lies at
    the fraction ``stamp_at`` of the sweep (0: at its start, Ouster-like; 1: at its end, Velodyne-like), and the
    returned times are ``(j / n_azimuth - stamp_at) * period``. ``skew=False`` casts every column from the
    stamp's pose (an ideal, instantaneous scanner; same times). ``progress`` wraps the scan loop (e.g. tqdm).
    """
    if n_scans < 1 or not 0.0 <= stamp_at <= 1.0 or period <= 0:
        raise ValueError("n_scans must be >= 1, stamp_at in [0, 1], period > 0")
    lidar = lidar or LidarModel()
    yaw_rate = np.radians(yaw_rate_deg)
    rng = np.random.default_rng(seed)
    scene = scene or plaza_scene(seed, speed / yaw_rate)
    phase, direction = rng.uniform(0.0, 2 * np.pi), float(rng.choice([-1.0, 1.0]))
    offsets = (np.arange(lidar.n_azimuth) / lidar.n_azimuth - stamp_at) * period  # column times vs the stamp
    out = SkewedSequence([], [], [], [], {"seed": seed, "speed_mps": speed, "yaw_rate_deg": yaw_rate_deg,
                                          "period_s": period, "stamp_at": stamp_at, "skew": skew,
                                          "direction": direction, "radius_m": speed / yaw_rate})
    ticks = range(n_scans) if progress is None else progress(range(n_scans))
    for k in ticks:
        stamp = k * period
        column_times = stamp + offsets if skew else np.full(lidar.n_azimuth, stamp)
        points, columns = skewed_scan(scene, circle_poses(column_times, phase, direction, speed, yaw_rate),
                                      lidar, rng)
        out.scans.append(points)
        out.times.append(offsets[columns].astype(np.float64))
        out.poses.append(circle_poses(np.array([stamp]), phase, direction, speed, yaw_rate)[0])
        out.stamps_ns.append(int(round(stamp * 1e9)))
    return out
