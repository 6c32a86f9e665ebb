"""The polish's wide stage (cemnet_ros.pipeline.steps.basin): GICP from afar, in the frame its target is placed in."""
import numpy as np
from street_scene import make_transform

from benchmarks.metrics import relative_error
from cemnet_ros.pipeline.map.gicp_cloud import gicp_cloud
from cemnet_ros.pipeline.steps.basin import gicp


def room(rng, n=6000):
    """Points on the floor and three walls of a 12 x 8 x 3 m room (sensor frame at its centre)."""
    u = rng.uniform(-1.0, 1.0, (n, 2))
    side = rng.integers(0, 4, n)
    points = np.zeros((n, 3))
    points[side == 0] = np.c_[6 * u[side == 0, 0], 4 * u[side == 0, 1], np.full((side == 0).sum(), -1.5)]
    points[side == 1] = np.c_[np.full((side == 1).sum(), 6.0), 4 * u[side == 1, 0], 1.5 * u[side == 1, 1]]
    points[side == 2] = np.c_[6 * u[side == 2, 0], np.full((side == 2).sum(), 4.0), 1.5 * u[side == 2, 1]]
    points[side == 3] = np.c_[6 * u[side == 3, 0], np.full((side == 3).sum(), -4.0), 1.5 * u[side == 3, 1]]
    return points + rng.normal(0.0, 0.01, points.shape)


def test_gicp_finds_the_motion_from_a_metre_and_degrees_off_in_the_target_s_placed_frame():
    rng = np.random.default_rng(0)
    scene = room(rng)
    T_target_source = make_transform(yaw=np.radians(15.0), t=(0.8, -0.4, 0.05))
    source_points = (scene - T_target_source[:3, 3]) @ T_target_source[:3, :3]  # the scene seen from the source
    T_map_target = make_transform(yaw=np.radians(-70.0), t=(20.0, 5.0, 1.0))  # where the map keeps its last scan
    target = gicp_cloud(scene, 0.2).placed(T_map_target)
    source = gicp_cloud(source_points, 0.2)
    T_found = gicp(target, source, T_map_target, max_distance=1.5, iters=60)  # started at the target's pose
    metres, degrees = relative_error(T_found, T_map_target @ T_target_source)
    assert metres < 0.03 and degrees < 0.2, (metres, degrees)
    again = gicp(target, source, T_map_target, max_distance=1.5, iters=60)
    np.testing.assert_array_equal(again, T_found)  # one thread: the same answer every time


def test_placing_a_cloud_keeps_its_points_and_copies_the_pose():
    cloud = gicp_cloud(room(np.random.default_rng(1)), 0.3)
    pose = make_transform(t=(1.0, 2.0, 3.0))
    placed = cloud.placed(pose)
    pose[0, 3] = 99.0
    assert placed.points is cloud.points and placed.pose[0, 3] == 1.0
    np.testing.assert_array_equal(cloud.pose, np.eye(4))
