"""The constant-velocity motion model."""
import numpy as np
from street_scene import make_transform

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
    half = se3_power(step, 0.5)
    np.testing.assert_allclose(half @ half, step, atol=1e-9)
