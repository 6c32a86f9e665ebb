"""The replay is the node offline: for the same bag and parameters, cemnet-replay and align_node's session (built
as the node builds it, from its ROS parameter values) give the same poses and step records, bit for bit."""
from __future__ import annotations

import numpy as np

from cemnet_ros.replay.bag_io import BagReader
from cemnet_ros.ros.node_config import configs_from_parameters
from cemnet_ros.runtime.aligner_session import AlignerSession
from cemnet_ros.runtime.extrinsic import BaseFrame, pose_from_xyz_rpy
from cemnet_ros.tools.replay_cli import configure, parse_args, replay

PARAMETERS = {"registration.cem_preset": "refine", "seed": 3,
              "base_to_sensor": (0.3, -0.1, 1.7, 0.01, -0.02, 0.5)}
UNTIMED = ("index", "latency_s")  # the bag's message index (the session is not told it) and the wall clock


def _flags(parameters: dict) -> list[str]:
    flags = []
    for name, value in parameters.items():
        flags += [f"--{name}", *(map(str, value) if isinstance(value, tuple) else [str(value)])]
    return flags


def _record(result) -> dict:
    """The replay summary's step record of one session result, without its index and latency."""
    step, out = result.step, result.out
    return {"stamp_ns": step.stamp_ns, "fitness": step.fitness, "accepted": step.accepted, "reason": step.reason,
            "n_points": step.n_points, "first": step.relative is None, "recovered": step.recovered,
            "recovery_reason": step.recovery_reason, "degenerate": step.degenerate, "signals": step.signals,
            "origin": step.origin, "effort": step.effort, "polishes": step.polishes, "vouched_late": step.vouched_late,
            "twist_known": out.twist_known, "linear_m_s": out.linear.tolist(), "angular_rad_s": out.angular.tolist()}


def test_replay_and_node_session_give_the_same_poses_and_step_records(tiny_bag, tmp_path):
    config = configure(parse_args([str(tiny_bag), "--out", str(tmp_path / "replay"), "--quiet", "--no-plot",
                                   *_flags(PARAMETERS)]))
    replayed, _, _ = replay(config)

    node, pipeline = configs_from_parameters(PARAMETERS)
    assert (node, pipeline) == (config.node, config.pipeline)  # flags and ROS parameters: one configuration
    session = AlignerSession(pipeline, node, BaseFrame(pose_from_xyz_rpy(node.base_to_sensor)))
    assert session.load() is not None
    poses, records = [], []
    with BagReader(tiny_bag) as reader:
        for scan in reader.clouds():
            session.begin_scan()
            result = session.process(scan, scan.frame_id, None)
            poses.append(result.out.T_odom_base)
            records.append(_record(result))

    assert len(poses) == len(replayed.poses) == 4
    for mine, theirs in zip(poses, replayed.poses):
        np.testing.assert_array_equal(mine, theirs)
    assert records == [{k: v for k, v in step.items() if k not in UNTIMED} for step in replayed.steps]
    assert not np.allclose(poses[-1], poses[0])  # the scans moved: the comparison is not of identities
