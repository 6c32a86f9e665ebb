#!/usr/bin/env python3
"""Make the bundled rosbag2 (mcap) replay bags: a ray-cast synthetic LiDAR run, 6 KITTI scans, 50 7-Scenes frames.

Every bag holds ``sensor_msgs/msg/PointCloud2`` scans (float32 x, y, z, little endian; header.frame_id = the
sensor frame) on ``/points`` and ``geometry_msgs/msg/PoseStamped`` ground truth (sensor pose in the world
frame, same stamps) on ``/ground_truth``. Output is deterministic (seeded) and written atomically.

    python scripts/make_bags.py                      # all bags into bags/ (KITTI/7-Scenes need ../shared)
    python scripts/make_bags.py synthetic --out bags # only the synthetic bag (no external data needed)
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # runnable from a fresh checkout without `pip install`
    sys.path.insert(0, str(REPO))

from cemnet_ros.pipeline.preprocess import voxel_downsample  # noqa: E402
from cemnet_ros.replay.bag_io import BagWriter  # noqa: E402

SHARED = REPO.parent / "shared" / "data"
WORLD_FRAME = "world"


# ----------------------------------------------------------------------------------------------------------
# Synthetic scene: analytic ray casting against a ground plane, oriented boxes and vertical cylinders.
# ----------------------------------------------------------------------------------------------------------
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


# ----------------------------------------------------------------------------------------------------------
# Real data
# ----------------------------------------------------------------------------------------------------------
def _se3(rows: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :4] = np.asarray(rows, dtype=np.float64).reshape(3, 4)
    return out


def kitti_frames(root: Path, crop: float, voxel: float):
    """Yield (points (n,3) float32 in the velodyne frame, T_world_velo) with world = first velodyne frame."""
    tr = None
    for line in (root / "calib.txt").read_text().splitlines():
        if line.startswith("Tr:"):
            tr = _se3([float(v) for v in line.split()[1:]])
    if tr is None:
        raise ValueError(f"{root / 'calib.txt'} has no 'Tr:' line")
    tr_inv = np.linalg.inv(tr)
    poses = [_se3([float(v) for v in ln.split()]) for ln in (root / "poses.txt").read_text().splitlines() if ln.strip()]
    scans = sorted((root / "velodyne").glob("*.bin"))
    if len(scans) != len(poses):
        raise ValueError(f"{len(scans)} scans but {len(poses)} poses in {root}")
    for scan, cam_pose in zip(scans, poses):
        pts = np.fromfile(scan, dtype=np.float32).reshape(-1, 4)[:, :3]
        pts = pts[np.linalg.norm(pts, axis=1) <= crop]
        yield voxel_downsample(pts, voxel), tr_inv @ cam_pose @ tr


def rgbd_frames(root: Path, stride: int, voxel: float, max_depth: float):
    """Yield (points (n,3) float32 in the camera optical frame, T_world_camera) for each depth frame."""
    from PIL import Image  # pillow ships with matplotlib

    fx = fy = 585.0
    cx, cy = 320.0, 240.0
    intr = root / "camera-intrinsics.txt"
    if intr.exists():
        k = np.loadtxt(intr)
        fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
    for depth_png in sorted((root / "rgbd-frames").glob("frame-*.depth.png")):
        depth = np.asarray(Image.open(depth_png), dtype=np.float64)[::stride, ::stride] / 1000.0
        v, u = np.mgrid[0 : depth.shape[0] * stride : stride, 0 : depth.shape[1] * stride : stride]
        ok = (depth > 0) & (depth <= max_depth)
        z = depth[ok]
        pts = np.stack([(u[ok] - cx) * z / fx, (v[ok] - cy) * z / fy, z], axis=-1)
        pose = np.loadtxt(depth_png.with_name(depth_png.name.replace(".depth.png", ".pose.txt")))
        yield voxel_downsample(pts, voxel), pose


# ----------------------------------------------------------------------------------------------------------
# Bags
# ----------------------------------------------------------------------------------------------------------
def write_bag(path: Path, frames, sensor_frame: str, period_ns: int, start_ns: int = 1_700_000_000_000_000_000) -> dict:
    """Write (points, T_world_sensor) frames as /points + /ground_truth; returns a small summary."""
    counts = []
    with BagWriter(path) as bag:
        for i, (points, pose) in enumerate(frames):
            stamp = start_ns + i * period_ns
            bag.write_cloud("/points", points, sensor_frame, stamp)
            bag.write_pose("/ground_truth", pose, WORLD_FRAME, stamp)
            counts.append(len(points))
    return {"bag": str(path), "scans": len(counts), "points_mean": int(np.mean(counts)), "bytes": path.stat().st_size}


BAG_NAMES = {"synthetic": "synthetic_lidar.mcap", "kitti": "kitti_00_6scans.mcap", "rgbd": "rgbd_7scenes_50.mcap"}


def make_synthetic(out: Path, n_scans: int = 20, seed: int = 0) -> dict:
    scene, lidar = courtyard_scene(), LidarModel()
    rng = np.random.default_rng(seed)
    frames = ((lidar_scan(scene, pose, lidar, rng), pose) for pose in synthetic_trajectory(n_scans))
    return write_bag(out / BAG_NAMES["synthetic"], frames, "lidar", 100_000_000)


def make_kitti(out: Path, crop: float = 50.0, voxel: float = 0.2) -> dict:
    frames = kitti_frames(SHARED / "kitti_sample", crop, voxel)
    return write_bag(out / BAG_NAMES["kitti"], frames, "velodyne", 100_000_000)


def make_rgbd(out: Path, stride: int = 2, voxel: float = 0.02, max_depth: float = 4.0) -> dict:
    frames = rgbd_frames(SHARED / "rgbd_7scenes", stride, voxel, max_depth)
    return write_bag(out / BAG_NAMES["rgbd"], frames, "camera_depth_optical_frame", 33_333_333)


MAKERS = {"synthetic": make_synthetic, "kitti": make_kitti, "rgbd": make_rgbd}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("which", nargs="*", help=f"bags to make: {', '.join(MAKERS)} (default: all)")
    parser.add_argument("--out", type=Path, default=REPO / "bags", help="output directory (default: bags/)")
    parser.add_argument("--force", action="store_true", help="overwrite existing bags")
    args = parser.parse_args(argv)
    unknown = sorted(set(args.which) - set(MAKERS))
    if unknown:
        parser.error(f"unknown bag(s) {unknown}; choose from {list(MAKERS)}")
    args.out.mkdir(parents=True, exist_ok=True)
    for name in args.which or list(MAKERS):
        target = args.out / BAG_NAMES[name]
        if name != "synthetic" and not SHARED.exists():
            print(f"skip {name}: {SHARED} not found (needed for the real data)")
            continue
        if target.exists() and not args.force:
            print(f"skip {name}: {target} exists (use --force to rebuild)")
            continue
        target.unlink(missing_ok=True)
        info = MAKERS[name](args.out)
        print(f"{name}: {info['scans']} scans, {info['points_mean']} points/scan, "
              f"{info['bytes'] / 1e6:.2f} MB -> {info['bag']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
