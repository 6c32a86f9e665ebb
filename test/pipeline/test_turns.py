"""The turns of the last pose: a grid of yaws and tilts about the sensor, the position kept."""
from __future__ import annotations

import numpy as np
from street_scene import make_transform

from cemnet_ros.core.geometry import rotation_angle_deg
from cemnet_ros.pipeline.config import RecoveryConfig
from cemnet_ros.pipeline.steps.starts import turns


def test_the_turns_span_the_yaws_and_tilts_about_the_pose_and_keep_its_position():
    T_last = make_transform(yaw=0.7, t=(4.0, -2.0, 1.0))
    turned = turns(T_last, RecoveryConfig(turn_yaw_deg=90.0, turn_step_deg=30.0, turn_tilt_deg=20.0))
    assert len(turned) == 7 * 5 - 1  # yaws -90..90 in 30 deg, each level and tilted 4 ways; the pose itself not
    for T in turned:
        np.testing.assert_allclose(T[:3, 3], T_last[:3, 3])
        np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12)
    angles = sorted(rotation_angle_deg(T_last[:3, :3].T @ T[:3, :3]) for T in turned)
    assert 19.9 < angles[0] and angles[-1] < 93.0
    z_turns = [T for T in turned if np.isclose(T[:3, 2] @ T_last[:3, 2], 1.0)]  # about the sensor's own z
    assert len(z_turns) == 6


def test_no_turns_when_disabled_and_yaw_only_without_tilt():
    T_last = make_transform(yaw=0.2)
    assert turns(T_last, RecoveryConfig(turn_yaw_deg=0.0)) == []
    assert len(turns(T_last, RecoveryConfig(turn_yaw_deg=60.0, turn_step_deg=30.0, turn_tilt_deg=0.0))) == 4
