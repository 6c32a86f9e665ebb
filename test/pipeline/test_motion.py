"""The constant-velocity motion model."""
import numpy as np
from street_scene import make_transform

from cemnet_ros.core.geometry import se3_log
from cemnet_ros.pipeline.steps.motion import ConstantVelocity, se3_power


def test_constant_velocity_repeats_and_rescales_the_last_motion():
    model = ConstantVelocity()
    np.testing.assert_array_equal(model.predict(5), np.eye(4))
    step = make_transform(yaw=0.1, t=(1.0, 0.2, 0.0))
    model.update(np.eye(4), 0)
    np.testing.assert_array_equal(model.predict_relative(100), np.eye(4))
    model.update(step, 100)
    np.testing.assert_allclose(model.predict_relative(200), step, atol=1e-9)
    np.testing.assert_allclose(model.predict(200), step @ step, atol=1e-9)
    np.testing.assert_allclose(model.predict_relative(300), step @ step, atol=1e-9)  # a dropped scan
    np.testing.assert_allclose(model.predict_relative(1300), np.linalg.matrix_power(step, 12), atol=1e-9)  # a gap
    half = se3_power(step, 0.5)
    np.testing.assert_allclose(half @ half, step, atol=1e-9)


def test_the_model_owns_its_time_the_last_stamp_the_usual_step_and_the_velocity():
    model = ConstantVelocity()
    assert model.last_stamp is None and model.period_ns is None and model.velocity() is None
    assert model.dt_ratio(100) == 1.0  # no usual step yet
    step = make_transform(yaw=0.1, t=(1.0, 0.2, 0.0))
    model.update(np.eye(4), 0)
    assert model.last_stamp == 0 and model.period_ns is None and model.velocity() is None
    model.update(step, 100_000_000)
    assert model.period_ns == 100_000_000 and model.dt_ratio(300_000_000) == 2.0
    np.testing.assert_allclose(model.velocity(), se3_log(step) * 10.0, atol=1e-9)  # per second
    model.update(step @ step, 300_000_000)  # a dropped scan: the usual step moves a tenth of the way
    assert model.last_stamp == 300_000_000 and model.period_ns == 110_000_000
    np.testing.assert_allclose(model.velocity(), se3_log(step) * 5.0, atol=1e-9)
    model.reset()
    assert model.last_stamp is None and model.period_ns is None and model.velocity() is None


def test_a_restart_on_an_unvouched_pose_keeps_the_motion_of_the_last_vouched_step():
    model = ConstantVelocity()
    step = make_transform(yaw=0.05, t=(1.5, 0.0, 0.0))
    model.update(np.eye(4), 0)
    model.update(step, 100)  # vouched: 1.5 m a step
    model.update(step @ step, 200, vouched=False)  # a failed step: the prediction
    anchor = make_transform(yaw=0.3, t=(2.0, 4.0, 0.0))  # where the map restarts: a guess 4 m to the side
    model.restart_at(anchor, 300)
    assert model.last_stamp == 300
    np.testing.assert_allclose(model.predict_relative(400), step, atol=1e-9)  # not the jump into the guess
    np.testing.assert_allclose(model.velocity(), se3_log(step) / 100e-9, atol=1e-6)
    model.update(anchor @ step @ make_transform(t=(0.0, 0.3, 0.0)), 400, vouched=False)  # a degenerate step
    model.restart_at(anchor @ step @ step, 500)  # its successor restarts the map again
    np.testing.assert_allclose(model.predict_relative(600), step, atol=1e-9)


def test_a_restart_before_any_vouched_motion_leaves_no_velocity():
    model = ConstantVelocity()
    model.update(np.eye(4), 0)
    model.restart_at(make_transform(t=(3.0, 0.0, 0.0)), 100)
    assert not model.has_velocity and model.velocity() is None
    np.testing.assert_array_equal(model.predict_relative(200), np.eye(4))
