"""NEES of the published covariance (benchmarks.nees): its error's parameterisation and its statistics."""
import numpy as np
from street_scene import make_transform

from benchmarks.nees import CHI2_95, consistency, nees, step_consistency, step_error
from cemnet_ros.core.geometry import so3_exp
from cemnet_ros.runtime.extrinsic import BaseFrame, pose_from_xyz_rpy

RNG_SEED = 7


def random_covariance(rng, scale=(0.02, 0.01)):
    """A full SPD 6x6 covariance, ROS order, translation std ~scale[0] m, rotation ~scale[1] rad."""
    a = rng.normal(size=(6, 6)) * np.r_[np.full(3, scale[0]), np.full(3, scale[1])][:, None]
    return a @ a.T + np.diag(np.r_[np.full(3, scale[0]), np.full(3, scale[1])] ** 2) * 0.1


def perturbed(T, error):
    """T moved by a ROS-order error [v, w]: R <- exp([w]x) R about its own position, t <- t + v."""
    out = T.copy()
    out[:3, :3] = so3_exp(error[3:]) @ T[:3, :3]
    out[:3, 3] = T[:3, 3] + error[:3]
    return out


def test_step_error_is_the_left_rotation_about_the_position_and_the_translation_in_odom_axes():
    world_prev = make_transform(t=(10.0, -3.0, 1.0), yaw=0.7)  # the truth's world is not odom
    world_curr = world_prev @ make_transform(t=(1.2, 0.1, 0.0), yaw=0.2)
    odom_prev = make_transform(t=(2.0, 5.0, 0.0), yaw=-1.1)
    odom_curr_true = odom_prev @ np.linalg.inv(world_prev) @ world_curr
    error = np.array([0.03, -0.02, 0.01, 0.002, -0.004, 0.03])
    np.testing.assert_allclose(step_error(odom_prev, perturbed(odom_curr_true, error), world_prev, world_curr),
                               error, atol=1e-12)


def test_errors_drawn_from_the_covariance_give_nees_6_and_95_percent_within_the_bound():
    rng = np.random.default_rng(RNG_SEED)
    covariance = random_covariance(rng)
    errors = rng.multivariate_normal(np.zeros(6), covariance, size=4000)
    stats = consistency([nees(e, covariance) for e in errors])
    assert abs(stats["mean"] - 6.0) < 0.25 and abs(stats["within_95"] - 0.95) < 0.015
    over_confident = consistency([nees(e, covariance / 4) for e in errors])
    assert abs(over_confident["ratio"] - 4.0) < 0.2 and over_confident["within_95"] < 0.7
    blocks = step_consistency(list(errors), [covariance] * len(errors))
    assert abs(blocks["translation"]["mean"] - 3.0) < 0.15 and abs(blocks["rotation"]["mean"] - 3.0) < 0.15
    assert round(CHI2_95[6], 2) == 12.59 and consistency([])["mean"] is None


def test_the_base_frames_covariance_is_consistent_with_its_errors_through_an_extrinsic():
    """Errors of the sensor's pose drawn from the pipeline's covariance (about the sensor, sensor0 axes) become
    base errors whose NEES against BaseFrame.covariance is 6: the node's change of frame is the right one."""
    rng = np.random.default_rng(RNG_SEED + 1)
    base = BaseFrame(pose_from_xyz_rpy((1.5, -0.3, 0.8, 0.1, -0.2, 1.2)))  # a lever arm and a rotation
    sensor_prev = make_transform(t=(4.0, 1.0, 0.3), yaw=0.4)
    sensor_curr = sensor_prev @ make_transform(t=(0.9, 0.2, 0.05), yaw=0.15)
    covariance_sensor = random_covariance(rng)
    covariance_base = base.covariance(covariance_sensor, sensor_curr)
    values = []
    for e in rng.multivariate_normal(np.zeros(6), covariance_sensor, size=3000):
        published = base.pose(perturbed(sensor_curr, e))
        values.append(nees(step_error(base.pose(sensor_prev), published, base.pose(sensor_prev),
                                      base.pose(sensor_curr)), covariance_base))
    assert abs(np.mean(values) - 6.0) < 0.35
