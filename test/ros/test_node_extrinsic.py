"""align_node's extrinsic from TF (a stand-in buffer: no tf2_ros on the pip wheels): one that arrives after the
first output is ignored with a warning, so odom does not jump; one there from the start is used."""
from __future__ import annotations

import os

import numpy as np
import pytest

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # read when the DDS participant is created

from node_harness import EXTRINSIC, FIRST_TIMEOUT, POSES, StandInBuffer, pose_of, scan_msg, transform, wait_for  # noqa: E402

from benchmarks.metrics import relative_error  # noqa: E402
from cemnet_ros.runtime.extrinsic import pose_from_xyz_rpy  # noqa: E402

pytestmark = pytest.mark.dds


def _expected(k, T_base_sensor):
    return T_base_sensor @ np.linalg.inv(POSES[0]) @ POSES[k] @ np.linalg.inv(T_base_sensor)


def test_a_tf_extrinsic_after_the_first_output_is_ignored_and_odom_does_not_jump(harness_factory):
    harness = harness_factory()
    harness.node.alignment.tf_buffer = buffer = StandInBuffer()
    outputs = [harness.send(scan_msg(0), timeout=FIRST_TIMEOUT)]
    buffer.transform = transform(EXTRINSIC)  # TF comes up after the first pose went out
    outputs += [harness.send(scan_msg(k), timeout=FIRST_TIMEOUT) for k in range(1, 4)]
    for k, odom in enumerate(outputs):  # base_to_sensor (the sensor is the base) throughout
        trans_err, rot_err = relative_error(pose_of(odom), _expected(k, np.eye(4)))
        assert trans_err < 0.02 * k + 0.01 and rot_err < 0.1 * k + 0.01, (k, trans_err, rot_err)
    assert wait_for(lambda: "warning_extrinsic" in harness.values(), 5.0), harness.values()
    assert "arrived after the first output" in harness.values()["warning_extrinsic"]
    assert harness.diagnostics[-1].level == b"\x01" and "ignored" in harness.diagnostics[-1].message
    assert wait_for(lambda: any("arrived after the first output" in log.msg for log in harness.logs), 5.0)


def test_a_tf_extrinsic_there_from_the_start_is_used(harness_factory):
    harness = harness_factory()
    harness.node.alignment.tf_buffer = buffer = StandInBuffer()
    buffer.transform = transform(EXTRINSIC)
    outputs = [harness.send(scan_msg(k), timeout=FIRST_TIMEOUT) for k in range(3)]
    T_base_sensor = pose_from_xyz_rpy(EXTRINSIC)
    for k, odom in enumerate(outputs):
        trans_err, rot_err = relative_error(pose_of(odom), _expected(k, T_base_sensor))
        assert trans_err < 0.02 * k + 0.01 and rot_err < 0.1 * k + 0.01, (k, trans_err, rot_err)
    assert "warning_extrinsic" not in harness.values()
