"""The pose graph (benchmarks.pose_graph) shares a loop closure's error between the steps by their covariances."""
import numpy as np
from street_scene import make_transform

from benchmarks.pose_graph import close_loop
from cemnet_ros.runtime.extrinsic import in_body_axes


def diagonal(translation_var, rotation_var=1e-6):
    return np.diag(np.r_[np.asarray(translation_var, dtype=float), np.full(3, rotation_var)])


def test_a_loop_closure_moves_each_step_in_proportion_to_its_variance():
    """Five 1 m steps along x; the closure says the end is 0.1 m further. A linear problem: step k takes
    0.1 * var_k / sum(var) of the correction, so the step with 9x the variance takes 9x the share."""
    variances = np.array([0.01, 0.01, 0.09, 0.01, 0.01])
    poses = [make_transform(t=(float(k), 0.0, 0.0)) for k in range(6)]
    covariances = [None] + [diagonal((v, 1e-4, 1e-4)) for v in variances]
    closed = close_loop(poses, covariances, make_transform(t=(5.1, 0.0, 0.0)), closure_std=(1e-5, 1e-5))
    steps = np.diff([T[0, 3] for T in closed])
    np.testing.assert_allclose(steps - 1.0, 0.1 * variances / variances.sum(), atol=1e-5)
    assert abs(closed[-1][0, 3] - 5.1) < 1e-4


def test_the_covariance_is_read_in_the_base_axes_of_the_steps_pose():
    """Two steps with the robot turned 90 deg: each step is loose along its own base x only. An error along odom
    y is absorbed by the step whose base x points along odom y (the second), not by the first."""
    poses = [np.eye(4), make_transform(t=(1.0, 0.0, 0.0)), make_transform(t=(1.0, 1.0, 0.0), yaw=np.pi / 2)]
    loose_along_x = diagonal((0.04, 1e-6, 1e-6))  # in the step's base axes
    rotate = np.zeros((6, 6))
    rotate[:3, :3] = rotate[3:, 3:] = poses[2][:3, :3]
    published = [None, loose_along_x, rotate @ loose_along_x @ rotate.T]  # as the node publishes: odom axes
    body = [None] + [in_body_axes(c, T) for c, T in zip(published[1:], poses[1:])]
    T_first_last = poses[2].copy()
    T_first_last[1, 3] += 0.05  # the end is 5 cm further along odom y
    closed = close_loop(poses, body, T_first_last, closure_std=(1e-5, 1e-5))
    np.testing.assert_allclose(closed[1][:3, 3], poses[1][:3, 3], atol=2e-3)  # the first step kept
    np.testing.assert_allclose(closed[2][:3, 3], [1.0, 1.05, 0.0], atol=2e-3)
