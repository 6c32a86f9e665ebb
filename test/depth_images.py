"""Small synthetic depth images of planes whose geometry is known, in the 7-Scenes folder layout
(for the tests of cemnet_ros.data.rgbd and cemnet_ros.eval.sevenscenes)."""
import numpy as np
from PIL import Image
from scipy.spatial.transform import Rotation
from shared_data import SHARED

from cemnet_ros.data.rgbd import Intrinsics

SEVENSCENES = SHARED / "data" / "rgbd_7scenes"

K = Intrinsics(60.0, 55.0, 40.5, 29.5)  # an 80 x 60 image, fx != fy so that a swap would show
SHAPE = (60, 80)


def camera_pose(rotvec, translation) -> np.ndarray:
    """4x4 T_world_camera from a rotation vector and a translation."""
    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    out[:3, 3] = translation
    return out


def plane_depth_mm(normal, offset, T_world_camera) -> np.ndarray:
    """Depth (uint16 mm) of the world plane ``normal . p = offset`` seen by a camera at ``T_world_camera``."""
    R, t = T_world_camera[:3, :3], T_world_camera[:3, 3]
    v, u = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    rays = np.stack([(u - K.cx) / K.fx, (v - K.cy) / K.fy, np.ones(SHAPE)], axis=-1)  # z = 1 per ray
    z = (offset - normal @ t) / (rays @ R.T @ normal)  # p_world = R (z ray) + t on the plane
    return np.round(z * 1000.0).astype(np.uint16)


def write_folder(root, depths, poses) -> None:
    """camera-intrinsics.txt and rgbd-frames/frame-NNNNNN.{depth.png,pose.txt} under ``root``."""
    (root / "rgbd-frames").mkdir(parents=True)
    np.savetxt(root / "camera-intrinsics.txt", [[K.fx, 0, K.cx], [0, K.fy, K.cy], [0, 0, 1]])
    for i, (depth, pose) in enumerate(zip(depths, poses)):
        Image.fromarray(depth).save(root / "rgbd-frames" / f"frame-{i:06d}.depth.png")
        np.savetxt(root / "rgbd-frames" / f"frame-{i:06d}.pose.txt", pose)


WALL_NORMAL, WALL_OFFSET = np.array([0.2, -0.1, 1.0]) / np.linalg.norm([0.2, -0.1, 1.0]), 2.5
POSES = [camera_pose([0.0, 0.0, 0.0], [0.0, 0.0, 0.0]), camera_pose([0.05, -0.1, 0.02], [0.3, -0.1, 0.2])]
