"""align_node with use_sim_time and no /clock: diagnostics still come (a steady timer), and the node says why
its scans are refused (ROS time is 0, so real stamps are ahead of it)."""
from __future__ import annotations

import os
import time

import pytest

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # read when the DDS participant is created

from node_harness import FIRST_TIMEOUT, scan_msg, wait_for  # noqa: E402

pytestmark = pytest.mark.dds
EPOCH_S = 1_700_000_000  # a real sensor's stamp: far ahead of a clock that reads 0


def test_without_clock_diagnostics_publish_and_warn_and_rejections_explain(harness_factory):
    harness = harness_factory({"use_sim_time": True})
    assert wait_for(lambda: harness.diagnostics, 10.0), "no diagnostics while ROS time stands at 0"
    for k in range(5):
        msg = scan_msg(k)
        msg.header.stamp.sec += EPOCH_S
        harness.send(msg, expect_output=False)
        time.sleep(0.8)
    assert wait_for(lambda: "no /clock has arrived" in harness.diagnostics[-1].message, 10.0), \
        harness.diagnostics[-1].message
    assert harness.values()["ros_time_unset"] == "True" and harness.diagnostics[-1].level == b"\x01"
    assert wait_for(lambda: any("no /clock has arrived" in log.msg for log in harness.logs), 5.0)
    assert wait_for(lambda: len(harness.statuses) == 5, FIRST_TIMEOUT), "a scan without a verdict"
    assert all("clock reads 0" in status.message for status in harness.statuses), harness.statuses[0].message
    assert not harness.odometry
