"""A ray-cast courtyard pair with a large motion, for the recovery's tests (metres, sensor frames)."""
import numpy as np
from scipy.spatial.transform import Rotation

from cemnet_ros.data.scenes import COURTYARD_BOUNDS, LidarModel, courtyard_scene, lidar_scan, random_sensor_pose


def courtyard_pair(seed: int = 0, yaw_deg: float = 140.0, translation=(3.0, -2.0, 0.0)):
    """(first scan, second scan, T_first_second): 16-beam scans from a random pose and that pose moved."""
    rng, scene = np.random.default_rng(seed), courtyard_scene()
    lidar = LidarModel(n_beams=16, n_azimuth=360)
    first = random_sensor_pose(COURTYARD_BOUNDS, rng, scene)
    motion = np.eye(4)
    motion[:3, :3] = Rotation.from_euler("z", yaw_deg, degrees=True).as_matrix()
    motion[:3, 3] = translation
    scans = [lidar_scan(scene, pose, lidar, rng).astype(np.float64) for pose in (first, first @ motion)]
    return scans[0], scans[1], motion
