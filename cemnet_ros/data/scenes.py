"""Ray-cast synthetic LiDAR scenes: analytic ray casting against a ground plane, oriented boxes and vertical cylinders.

``courtyard_scene`` (a walled courtyard, every pose component observable) made ``bags/synthetic_lidar.mcap``;
``corridor_scene`` is a long featureless corridor whose along-axis translation is unobservable.
Poses are T_world_sensor (4x4); scans are (n, 3) float32 points in the sensor frame.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation


@dataclass
class Box:
    """Oriented box: centre (3,), half extents (3,), rotation (3,3) box->world."""

    centre: np.ndarray
    half: np.ndarray
    rotation: np.ndarray


@dataclass
class Cylinder:
    """Vertical cylinder standing on z = z0."""

    x: float
    y: float
    radius: float
    z0: float
    height: float


@dataclass
class Scene:
    """Boxes and cylinders above a ground plane at ``ground_z`` (-inf: no ground plane)."""

    boxes: list[Box]
    cylinders: list[Cylinder]
    ground_z: float = 0.0


def _box(cx, cy, cz, hx, hy, hz, yaw_deg=0.0, pitch_deg=0.0, roll_deg=0.0) -> Box:
    rot = Rotation.from_euler("zyx", [yaw_deg, pitch_deg, roll_deg], degrees=True).as_matrix()
    return Box(np.array([cx, cy, cz], float), np.array([hx, hy, hz], float), rot)


def courtyard_scene() -> Scene:
    """A 70 m x 44 m walled courtyard with buildings, yawed crates, a tilted ramp and poles.

    Surfaces face all three axes (and several oblique directions), so every pose component is observable.
    """
    wall_h, t = 7.0, 0.4
    boxes = [
        # perimeter walls
        _box(15, -22, wall_h / 2, 35, t, wall_h / 2),
        _box(15, 22, wall_h / 2, 35, t, wall_h / 2),
        _box(-20, 0, wall_h / 2, t, 22, wall_h / 2),
        _box(50, 0, wall_h / 2, t, 22, wall_h / 2),
        # building blocks along the walls (facade steps break the corridor symmetry)
        _box(2, -18, 3.0, 5, 3.5, 3.0),
        _box(18, -17, 4.5, 4, 4.5, 4.5, yaw_deg=8),
        _box(33, -18.5, 2.0, 6, 3, 2.0),
        _box(-6, 17, 2.5, 6, 4, 2.5),
        _box(12, 18, 3.5, 5, 3.5, 3.5, yaw_deg=-6),
        _box(28, 17.5, 5.0, 4, 4, 5.0),
        # crates and obstacles inside, some yawed
        _box(6, -6, 0.6, 1.2, 0.8, 0.6, yaw_deg=25),
        _box(10, 7, 1.0, 1.5, 1.5, 1.0, yaw_deg=-35),
        _box(16, -3, 0.45, 0.9, 2.0, 0.45, yaw_deg=10),
        _box(-4, -8, 1.25, 2.0, 1.0, 1.25, yaw_deg=50),
        _box(22, 9, 0.75, 1.0, 1.0, 0.75),
        _box(-8, 6, 0.5, 0.5, 3.0, 0.5, yaw_deg=-15),
        # a tilted ramp and a leaning panel (oblique normals)
        _box(24, -7, 0.9, 4.0, 1.5, 0.15, pitch_deg=-12),
        _box(3, 11, 1.5, 2.0, 0.1, 1.5, yaw_deg=20, roll_deg=15),
    ]
    cylinders = [
        Cylinder(x, y, r, 0.0, h)
        for x, y, r, h in [
            (4, 4, 0.2, 4.0), (8, -11, 0.3, 5.0), (13, 3, 0.15, 3.5), (19, 13, 0.4, 3.0),
            (27, 2, 0.25, 4.5), (-3, 1, 0.35, 2.5), (31, -10, 0.2, 6.0), (-12, -12, 0.5, 3.0),
        ]
    ]
    return Scene(boxes, cylinders)


COURTYARD_BOUNDS = (-18.0, 48.0, -20.0, 20.0)  # x_min, x_max, y_min, y_max: inside the courtyard's walls


def corridor_scene(length: float = 120.0, width: float = 3.0, height: float = 3.0) -> Scene:
    """A straight featureless corridor along x, centred on the origin: floor (z = 0), ceiling, two walls.

    The ends are open (no end walls, no ground plane beyond): within a sensor range shorter than the distance
    to an end, every scan is the same whatever the sensor's x, so translation along the corridor is unobservable.
    """
    t, half_l, half_w = 0.2, length / 2.0, width / 2.0
    boxes = [
        _box(0.0, 0.0, -t / 2, half_l, half_w + t, t / 2),  # floor
        _box(0.0, 0.0, height + t / 2, half_l, half_w + t, t / 2),  # ceiling
        _box(0.0, -half_w - t / 2, height / 2, half_l, t / 2, height / 2 + t),  # right wall
        _box(0.0, half_w + t / 2, height / 2, half_l, t / 2, height / 2 + t),  # left wall
    ]
    return Scene(boxes, [], ground_z=-np.inf)


def inside_obstacle(scene: Scene, points: np.ndarray, margin: float = 0.0):
    """Whether each point ((3,) or (n, 3)) lies within ``margin`` metres of the inside of a box or cylinder.

    Returns a bool for one point, a (n,) bool array for several.
    """
    pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
    hit = np.zeros(len(pts), dtype=bool)
    for box in scene.boxes:
        hit |= np.all(np.abs((pts - box.centre) @ box.rotation) <= box.half + margin, axis=1)
    for c in scene.cylinders:
        near = np.hypot(pts[:, 0] - c.x, pts[:, 1] - c.y) <= c.radius + margin
        hit |= near & (pts[:, 2] >= c.z0 - margin) & (pts[:, 2] <= c.z0 + c.height + margin)
    return hit if np.ndim(points) == 2 else bool(hit[0])


def in_free_space(scene: Scene, positions: np.ndarray, bounds: tuple[float, float, float, float],
                  margin: float = 1.0) -> bool:
    """Whether every sensor position ((n, 3) metres) is inside ``bounds`` and ``margin`` clear of obstacles
    (checked at its height and at 0.3 m, the vehicle's body)."""
    positions = np.atleast_2d(positions)
    x, y = positions[:, 0], positions[:, 1]
    if not np.all((bounds[0] <= x) & (x <= bounds[1]) & (bounds[2] <= y) & (y <= bounds[3])):
        return False
    low = np.c_[x, y, np.full(len(x), 0.3)]
    return not np.any(inside_obstacle(scene, positions, margin)) and not np.any(inside_obstacle(scene, low, margin))


def random_sensor_pose(scene_bounds: tuple[float, float, float, float], rng: np.random.Generator,
                       scene: Scene | None = None, height: float = 1.8, tilt_deg: float = 1.0,
                       margin: float = 1.0) -> np.ndarray:
    """A T_world_sensor drawn inside ``scene_bounds`` (x_min, x_max, y_min, y_max): yaw uniform, z ~ ``height``
    (+-0.1 m), roll and pitch within +-``tilt_deg``; with ``scene``, at least ``margin`` m clear of its obstacles.
    """
    x_min, x_max, y_min, y_max = scene_bounds
    while True:
        xyz = np.array([rng.uniform(x_min, x_max), rng.uniform(y_min, y_max), height + rng.uniform(-0.1, 0.1)])
        if scene is None or not inside_obstacle(scene, xyz, margin):
            break
    pose = np.eye(4)
    roll, pitch = rng.uniform(-tilt_deg, tilt_deg, 2)
    pose[:3, :3] = Rotation.from_euler("zyx", [rng.uniform(-180.0, 180.0), pitch, roll], degrees=True).as_matrix()
    pose[:3, 3] = xyz
    return pose


def _ray_boxes(origin: np.ndarray, dirs: np.ndarray, boxes: list[Box], best: np.ndarray) -> None:
    for box in boxes:
        o = (origin - box.centre) @ box.rotation  # into the box frame
        d = dirs @ box.rotation
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / d
            t1 = (-box.half - o) * inv
            t2 = (box.half - o) * inv
        t_near = np.nanmax(np.minimum(t1, t2), axis=1)
        t_far = np.nanmin(np.maximum(t1, t2), axis=1)
        hit = (t_near <= t_far) & (t_far > 0)
        t_hit = np.where(t_near > 0, t_near, t_far)  # origin inside a box: its inner face
        np.minimum(best, np.where(hit, t_hit, np.inf), out=best)


def _ray_cylinders(origin: np.ndarray, dirs: np.ndarray, cylinders: list[Cylinder], best: np.ndarray) -> None:
    dx, dy, dz = dirs[:, 0], dirs[:, 1], dirs[:, 2]
    a = dx**2 + dy**2
    for c in cylinders:
        ox, oy = origin[0] - c.x, origin[1] - c.y
        b = 2 * (ox * dx + oy * dy)
        cc = ox**2 + oy**2 - c.radius**2
        disc = b**2 - 4 * a * cc
        with np.errstate(invalid="ignore", divide="ignore"):
            t = (-b - np.sqrt(disc)) / (2 * a)
        z = origin[2] + t * dz
        side = (disc >= 0) & (t > 0) & (z >= c.z0) & (z <= c.z0 + c.height)
        with np.errstate(invalid="ignore", divide="ignore"):
            t_top = (c.z0 + c.height - origin[2]) / dz
        px, py = ox + t_top * dx, oy + t_top * dy
        top = (t_top > 0) & (px**2 + py**2 <= c.radius**2)
        np.minimum(best, np.where(side, t, np.inf), out=best)
        np.minimum(best, np.where(top, t_top, np.inf), out=best)


def raycast(scene: Scene, origin: np.ndarray, dirs: np.ndarray, max_range: float) -> np.ndarray:
    """Distance along each unit world-frame ray to the first surface (inf = no return within max_range)."""
    best = np.full(len(dirs), np.inf)
    with np.errstate(divide="ignore"):
        t_ground = (scene.ground_z - origin[2]) / dirs[:, 2]
    best = np.where(t_ground > 0, t_ground, best)
    _ray_boxes(origin, dirs, scene.boxes, best)
    _ray_cylinders(origin, dirs, scene.cylinders, best)
    best[best > max_range] = np.inf
    return best


@dataclass
class LidarModel:
    """Spinning multi-beam LiDAR: beams evenly spaced in elevation, uniform azimuth steps."""

    n_beams: int = 32
    n_azimuth: int = 1000
    elevation_deg: tuple[float, float] = (-25.0, 15.0)
    min_range: float = 0.5
    max_range: float = 100.0
    range_noise: float = 0.01  # metres, Gaussian

    def directions(self) -> np.ndarray:
        el = np.radians(np.linspace(*self.elevation_deg, self.n_beams))
        az = np.linspace(0.0, 2 * np.pi, self.n_azimuth, endpoint=False)
        el, az = np.meshgrid(el, az, indexing="ij")
        return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], -1).reshape(-1, 3)


def lidar_scan(scene: Scene, pose: np.ndarray, lidar: LidarModel, rng: np.random.Generator) -> np.ndarray:
    """Instantaneous scan from sensor pose T_world_sensor -> (n,3) float32 points in the sensor frame."""
    dirs_s = lidar.directions()
    ranges = raycast(scene, pose[:3, 3], dirs_s @ pose[:3, :3].T, lidar.max_range)
    keep = np.isfinite(ranges) & (ranges >= lidar.min_range)
    noisy = ranges[keep] + rng.normal(0.0, lidar.range_noise, keep.sum())
    return (dirs_s[keep] * noisy[:, None]).astype(np.float32)


def synthetic_trajectory(n_scans: int, step: float = 0.7) -> list[np.ndarray]:
    """Smooth car-like path: ~0.7 m and ~3 deg yaw per scan, with small roll/pitch/height oscillations."""
    poses, xy, heading = [], np.zeros(2), 0.0
    for i in range(n_scans):
        if i:
            heading += 0.05 + 0.02 * np.cos(0.7 * i)
            xy = xy + step * np.array([np.cos(heading), np.sin(heading)])
        pose = np.eye(4)
        roll, pitch = 0.015 * np.cos(0.4 * i), 0.02 * np.sin(0.5 * i)
        pose[:3, :3] = Rotation.from_euler("zyx", [heading, pitch, roll]).as_matrix()
        pose[:3, 3] = [xy[0], xy[1], 1.8 + 0.05 * np.sin(0.6 * i)]
        poses.append(pose)
    return poses
