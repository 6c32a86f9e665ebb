"""Full-size scans (~120k points, ~2 MB) over DDS between two processes with the shipped profile, at 10 Hz.

The node and the publisher are separate processes (Fast DDS reads the profile when a process's first
participant starts, so this test process, whose participants started long before, cannot be either side).
The publisher is this file run as a script: ray-cast 64-beam scans of the courtyard, best effort at 10 Hz.
"""
from __future__ import annotations

import json
import os
import random
import subprocess
import sys
import time

import numpy as np
import pytest

from cemnet_ros.ros.probe import PROFILE, dds_environment, node_log, start_node

pytestmark = [pytest.mark.dds, pytest.mark.slow]

N_SCANS = 50
NS = "/full"


def test_full_size_scans_at_10_hz_all_arrive_and_are_processed():
    env = {**os.environ, **dds_environment(), "FASTRTPS_DEFAULT_PROFILES_FILE": str(PROFILE),
           "ROS_DOMAIN_ID": str(random.randint(120, 200))}  # the shipped profile and a domain of its own
    node = start_node(NS, {"qos_reliability": "best_effort"}, env=env)
    try:
        run = subprocess.run([sys.executable, __file__], env=env, capture_output=True, text=True, timeout=300)
    finally:
        node.terminate()
        node.wait(20)
    assert run.returncode == 0, run.stderr[-2000:] + node_log(node)[-2000:]
    result = json.loads(run.stdout.strip().splitlines()[-1])
    assert result["points"] > 100_000 and result["bytes"] > 1_500_000
    assert result["odometry"] >= 0.99 * N_SCANS and result["verdicts_ok"] >= 0.99 * N_SCANS, result


def _publish() -> dict:
    """Wait until the node aligns, then N_SCANS at 10 Hz best effort; what came back."""
    import rclpy

    from cemnet_ros.data.scenes import LidarModel, courtyard_scene, lidar_scan, synthetic_trajectory
    from cemnet_ros.ros.probe import Probe, cloud_message, serialized, stamped

    scene, lidar, rng = courtyard_scene(), LidarModel(n_beams=64, n_azimuth=2000), np.random.default_rng(0)
    scans = [lidar_scan(scene, pose, lidar, rng) for pose in synthetic_trajectory(6, step=0.1)]
    clouds = [cloud_message(np.column_stack([s, np.zeros(len(s), np.float32)])) for s in scans + scans[-2:0:-1]]
    messages = serialized(clouds)
    rclpy.init()
    probe = Probe(NS, reliable=False, name="full_scan_publisher")
    try:
        deadline = time.monotonic() + 200.0  # the node loads its engine
        while not probe.odometry and time.monotonic() < deadline:
            probe.pub.publish(stamped(messages[0]))
            time.sleep(1.0)
        time.sleep(2.0)
        odometry0, verdicts0 = len(probe.odometry), len(probe.verdicts)
        start = time.monotonic()
        for i in range(N_SCANS):
            probe.pub.publish(stamped(messages[(i + 1) % len(messages)]))
            time.sleep(max(0.0, start + (i + 1) / 10.0 - time.monotonic()))
        time.sleep(3.0)
        verdicts = probe.verdicts[verdicts0:]
        return {"points": int(clouds[0].width), "bytes": len(messages[0]), "odometry": len(probe.odometry) - odometry0,
                "verdicts_ok": sum(v.level == 0 for v in verdicts), "verdicts": len(verdicts)}
    finally:
        probe.close()
        rclpy.try_shutdown()


if __name__ == "__main__":
    print(json.dumps(_publish()))
