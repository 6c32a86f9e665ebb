"""The extrinsic in use: TF's is taken before the first output, held after it; a later, different one is ignored
with a standing warning, and the diagnostics carry it."""
from types import SimpleNamespace

import numpy as np

from cemnet_ros.runtime.extrinsic import pose_from_xyz_rpy
from cemnet_ros.runtime.extrinsic_hold import ExtrinsicHold
from cemnet_ros.runtime.node_status import WARN, NodeStatus

PARAMETER = pose_from_xyz_rpy((0.0, 0.0, 1.0, 0.0, 0.0, 0.0))
TF = pose_from_xyz_rpy((0.3, -0.1, 1.7, 0.01, -0.02, 0.5))


def test_tf_before_the_first_output_is_taken():
    hold = ExtrinsicHold(PARAMETER)
    adopted, line = hold.offer(TF, "base_link <- lidar")
    assert adopted and hold.source == "tf" and hold.settled and hold.ignored is None
    np.testing.assert_array_equal(hold.T_base_sensor, TF)
    assert line == "extrinsic base_link <- lidar from TF"


def test_tf_after_the_first_output_is_ignored_when_it_differs():
    hold = ExtrinsicHold(PARAMETER)
    hold.output_published()
    adopted, line = hold.offer(TF, "base_link <- lidar")
    assert not adopted and hold.source == "base_to_sensor" and hold.settled
    np.testing.assert_array_equal(hold.T_base_sensor, PARAMETER)
    assert line == hold.ignored and "arrived after the first output" in line and "ignored" in line
    assert "(0.768 m, 28.68 deg)" in line  # how far apart they are


def test_tf_after_the_first_output_equal_to_the_parameter_is_no_warning():
    hold = ExtrinsicHold(PARAMETER)
    hold.output_published()
    adopted, line = hold.offer(PARAMETER.copy(), "base_link <- lidar")
    assert not adopted and hold.ignored is None and "matches base_to_sensor" in line


def test_a_standing_warning_is_in_every_report():
    status = NodeStatus(input_timeout=10.0)
    status.ready = True
    queue = SimpleNamespace(depth=0, drops=0, errors=0, latency_last_s=0.0, latency_mean_s=0.0, latency_max_s=0.0)
    status.input_arrived()
    assert status.report(queue, None).level == 0
    status.stand("extrinsic", "the TF extrinsic ... ignored")
    for _ in range(2):
        report = status.report(queue, None)
        assert report.level == WARN and report.message == "the TF extrinsic ... ignored"
        assert report.values["warning_extrinsic"] == "the TF extrinsic ... ignored"
