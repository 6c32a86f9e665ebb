"""replay = live: the replay bag holds align_node's topics, frames and twist; ground truth and /tf_static
copied; evo on the bag gives the replay's ATE."""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from cemnet_ros.io.trajectory_files import read_tum
from cemnet_ros.replay.bag_io import BagReader, BagWriter
from cemnet_ros.replay.trajectory import absolute_trajectory_error
from cemnet_ros.ros.node_config import NodeConfig
from cemnet_ros.tools.replay_cli import main

PIPELINE = ["--seed", "1", "--recovery.search.refine_preset", "tracking"]  # both runs' (one from a file, one flag)
T_BASE_LIDAR = (0.2, 0.0, 1.5, 0.0, 0.0, 0.0)  # the /tf_static of the test bag (copied, not used)
EXTRINSIC = (0.3, -0.1, 1.7, 0.01, -0.02, 0.5)


def _raw_messages(path: Path) -> dict:
    """topic -> (msgtype, [(bag ns, deserialized message, raw bytes)])."""
    from rosbags.highlevel import AnyReader

    out: dict = {}
    with AnyReader([path]) as reader:
        for conn, bag_ns, raw in reader.messages():
            entry = out.setdefault(conn.topic, (conn.msgtype, []))
            entry[1].append((bag_ns, reader.deserialize(raw, conn.msgtype), bytes(raw)))
    return out


def _pose_of(pose_msg) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    q, p = pose_msg.orientation, pose_msg.position
    out = np.eye(4)
    out[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    out[:3, 3] = [p.x, p.y, p.z]
    return out


def _tf_of(tf) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    q, t = tf.transform.rotation, tf.transform.translation
    out = np.eye(4)
    out[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    out[:3, 3] = [t.x, t.y, t.z]
    return out


@pytest.fixture(scope="module")
def tf_static_bag(tiny_bag, tmp_path_factory) -> Path:
    """The tiny bag plus a /tf_static base_link -> lidar (as a robot's bag has), copied message by message."""
    from cemnet_ros.runtime.extrinsic import pose_from_xyz_rpy

    path = tmp_path_factory.mktemp("bags") / "tiny_tf_static.mcap"
    with BagReader(tiny_bag) as reader, BagWriter(path) as bag:
        stamp0 = next(reader.clouds()).stamp_ns
        bag.write_transform("/tf_static", pose_from_xyz_rpy(T_BASE_LIDAR), "base_link", "lidar", stamp0)
        for topic in ("/points", "/ground_truth"):
            for bag_ns, msgtype, msg in reader.messages(topic):
                bag.write_message(topic, msgtype, msg, bag_ns)
    return path


@pytest.fixture(scope="module")
def live_replay(tf_static_bag, tmp_path_factory) -> Path:
    """cemnet-replay with the node's default output parameters."""
    out = tmp_path_factory.mktemp("replay") / "live"
    assert main([str(tf_static_bag), "--out", str(out), "--quiet", "--no-plot", *PIPELINE]) == 0
    return out


def test_replay_bag_is_what_align_node_publishes(live_replay, tf_static_bag):
    from cemnet_ros.replay.bag_io import UNKNOWN_VARIANCE

    got, given = _raw_messages(live_replay / "replay.mcap"), _raw_messages(tf_static_bag)
    assert {t: v[0] for t, v in got.items()} == {
        "/align_node/odometry": "nav_msgs/msg/Odometry", "/align_node/pose": "geometry_msgs/msg/PoseStamped",
        "/tf": "tf2_msgs/msg/TFMessage",  # no /align_node/aligned_cloud: publish_aligned_cloud is false
        "/ground_truth": "geometry_msgs/msg/PoseStamped", "/tf_static": "tf2_msgs/msg/TFMessage"}
    # Ground truth and /tf_static: copied unchanged (bag times, header stamps, poses: byte for byte).
    for topic in ("/ground_truth", "/tf_static"):
        assert [(ns, raw) for ns, _, raw in got[topic][1]] == [(ns, raw) for ns, _, raw in given[topic][1]], topic
    in_stamps = [ns for ns, _, _ in given["/points"][1]]
    odom = [m for _, m, _ in got["/align_node/odometry"][1]]
    poses = [m for _, m, _ in got["/align_node/pose"][1]]
    tfs = [m.transforms for _, m, _ in got["/tf"][1]]
    assert len(odom) == len(poses) == len(tfs) == len(in_stamps) == 4
    assert [ns for ns, _, _ in got["/align_node/odometry"][1]] == in_stamps
    _, est = read_tum(live_replay / "trajectory_tum.txt")
    for k, (o, p, (tf,)) in enumerate(zip(odom, poses, tfs)):
        stamp = (o.header.stamp.sec, o.header.stamp.nanosec)
        assert stamp == divmod(in_stamps[k], 1_000_000_000)
        assert (o.header.frame_id, o.child_frame_id, p.header.frame_id) == ("odom", "base_link", "odom")
        assert (tf.header.frame_id, tf.child_frame_id) == ("odom", "base_link")
        assert (tf.header.stamp.sec, tf.header.stamp.nanosec) == stamp == (p.header.stamp.sec, p.header.stamp.nanosec)
        T = _pose_of(o.pose.pose)
        np.testing.assert_allclose(_pose_of(p.pose), T, atol=1e-12)
        np.testing.assert_allclose(_tf_of(tf), T, atol=1e-12)
        np.testing.assert_allclose(T, est[k], atol=1e-6)  # the TUM file is the published trajectory
        assert np.all(np.diag(np.reshape(o.pose.covariance, (6, 6))) > 0)
    # Twist: unknown on the first scan (zero, 1e6 variances), then the base's motion per second in base_link.
    first = odom[0].twist
    assert np.allclose(np.reshape(first.covariance, (6, 6)), np.eye(6) * UNKNOWN_VARIANCE)
    assert [first.twist.linear.x, first.twist.linear.y, first.twist.linear.z] == [0.0] * 3
    for k in range(1, 4):
        tw, dt = odom[k].twist, (in_stamps[k] - in_stamps[k - 1]) * 1e-9
        linear = np.array([tw.twist.linear.x, tw.twist.linear.y, tw.twist.linear.z])
        motion = np.linalg.inv(_pose_of(odom[k - 1].pose.pose)) @ _pose_of(odom[k].pose.pose)
        np.testing.assert_allclose(linear, motion[:3, 3] / dt, atol=1e-6)
        assert 4.0 < np.linalg.norm(linear) < 10.0  # ~0.7 m per 0.1 s
        assert abs(tw.twist.angular.z) > 0.05  # a few degrees of yaw per scan
        cov = np.diag(np.reshape(tw.covariance, (6, 6)))
        assert np.all(cov > 0) and np.all(cov < UNKNOWN_VARIANCE)
    summary = json.loads((live_replay / "summary.json").read_text())
    assert summary["frames"] == {"odom_frame": "odom", "base_frame": "base_link", "base_to_sensor": [0.0] * 6}
    assert set(summary["replay_topics"]) == set(got)
    assert [s["twist_known"] for s in summary["steps"]] == [False, True, True, True]


def test_replay_node_parameters_from_config_and_flags(tiny_bag, live_replay, tmp_path):
    """Frames, extrinsic, invert_tf, fixed covariances and the aligned cloud: from --config and flags, as live."""
    from cemnet_ros.runtime.extrinsic import pose_from_xyz_rpy

    params = tmp_path / "node.yaml"
    params.write_text("/**:\n  ros__parameters:\n    odom_frame: map\n    base_frame: from_file\n"
                      f"    base_to_sensor: {list(EXTRINSIC)}\n    covariance_mode: fixed\n"
                      "    input_topic: ignored_offline\n    seed: 1\n")
    out = tmp_path / "out"
    assert main([str(tiny_bag), "--out", str(out), "--quiet", "--no-plot", "--config", str(params),
                 "--recovery.search.refine_preset", "tracking", "--base_frame", "robot", "--invert_tf", "true",
                 "--fixed_position_variance", "0.04", "--publish_aligned_cloud", "true",
                 "--aligned_cloud_voxel", "0.5"]) == 0
    got = _raw_messages(out / "replay.mcap")
    assert set(got) == {"/align_node/odometry", "/align_node/pose", "/tf", "/align_node/aligned_cloud",
                        "/ground_truth"}
    odom = [m for _, m, _ in got["/align_node/odometry"][1]]
    default = [m for _, m, _ in _raw_messages(live_replay / "replay.mcap")["/align_node/odometry"][1]]
    T_bs = pose_from_xyz_rpy(EXTRINSIC)
    for o, d, (_, tf_msg, _), (_, cloud, _) in zip(odom, default, got["/tf"][1], got["/align_node/aligned_cloud"][1]):
        assert (o.header.frame_id, o.child_frame_id) == ("map", "robot")
        T = _pose_of(o.pose.pose)  # the base's pose: T_base_sensor T_sensor0_sensor inv(T_base_sensor)
        np.testing.assert_allclose(T, T_bs @ _pose_of(d.pose.pose) @ np.linalg.inv(T_bs), atol=1e-3)
        (tf,) = tf_msg.transforms  # invert_tf: robot -> map
        assert (tf.header.frame_id, tf.child_frame_id) == ("robot", "map")
        np.testing.assert_allclose(_tf_of(tf), np.linalg.inv(T), atol=1e-9)
        np.testing.assert_allclose(np.reshape(o.pose.covariance, (6, 6)),
                                   np.diag([0.04] * 3 + [NodeConfig().fixed_orientation_variance] * 3))
        assert cloud.header.frame_id == "map" and 0 < cloud.width < 16 * 360  # the 0.5 m voxel grid
    # TUM file and ATE are the base frame's (what is published).
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frames"]["base_frame"] == "robot" and summary["node_config"]["invert_tf"] is True
    assert (summary["config"]["seed"], summary["config"]["recovery"]["search"]["refine_preset"]) == (1, "tracking")
    _, est = read_tum(out / "trajectory_tum.txt")
    _, gt = read_tum(out / "ground_truth_tum.txt")
    np.testing.assert_allclose(est, [_pose_of(o.pose.pose) for o in odom], atol=1e-6)
    assert absolute_trajectory_error(est, gt).rmse == pytest.approx(summary["accuracy"]["ate"]["rmse_m"], abs=1e-9)


def test_live_and_replay_fill_the_same_odometry(tmp_path):
    """align_node's rclpy message and the replay's rosbags one carry the same numbers (odometry_output)."""
    pytest.importorskip("nav_msgs.msg", reason="rclpy message packages not installed (no ROS)")
    from types import SimpleNamespace

    from rosbags.highlevel import AnyReader
    from std_msgs.msg import Header

    from cemnet_ros.ros import messages
    from cemnet_ros.runtime.extrinsic import BaseFrame, pose_from_xyz_rpy
    from cemnet_ros.runtime.odometry_output import odometry_output

    base = BaseFrame(pose_from_xyz_rpy(EXTRINSIC))
    rel = pose_from_xyz_rpy((0.7, 0.05, 0.01, 0.01, -0.02, 0.05))
    cov = np.diag([1e-4, 2e-4, 3e-4, 1e-5, 2e-5, 3e-5])
    steps = [SimpleNamespace(pose=np.eye(4), relative=None, covariance=cov, accepted=True),
             SimpleNamespace(pose=rel, relative=rel, covariance=cov, accepted=True),
             SimpleNamespace(pose=rel @ rel, relative=rel, covariance=cov * 2, accepted=False)]
    for mode in ("registration", "fixed"):
        node = NodeConfig(covariance_mode=mode)
        path = tmp_path / f"{mode}.mcap"
        outs = [odometry_output(s, base, dt, node, 100.0) for s, dt in zip(steps, (None, 0.1, 0.1))]
        live = [messages.odometry(Header(frame_id="odom"), "base_link", o) for o in outs]
        with BagWriter(path, overwrite=True) as bag:
            for k, o in enumerate(outs):
                bag.write_odometry("/o", o.T_odom_base, o.pose_covariance, "odom", "base_link", k + 1,
                                   linear=o.linear, angular=o.angular, twist_covariance=o.twist_covariance)
        with AnyReader([path]) as reader:
            replayed = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()]
        assert not outs[0].twist_known and outs[1].twist_known
        for a, b in zip(live, replayed):
            def numbers(m):
                t = m.twist.twist
                return np.concatenate([_pose_of(m.pose.pose).ravel(), m.pose.covariance, m.twist.covariance,
                                       [t.linear.x, t.linear.y, t.linear.z, t.angular.x, t.angular.y, t.angular.z]])
            np.testing.assert_allclose(numbers(a), numbers(b), rtol=1e-12, atol=1e-15)
            assert a.child_frame_id == b.child_frame_id == "base_link"


def _evo_ape() -> Path:
    try:
        import evo  # noqa: F401
    except ImportError:
        pytest.skip("evo not importable (pip install evo, or the 'bench' extra)")
    exe = Path(sys.executable).with_name("evo_ape")
    if not exe.exists():
        pytest.skip(f"evo is importable but {exe} is missing")
    return exe


def test_evo_on_replay_bag_alone_gives_the_replay_ate(live_replay, tmp_path):
    """`evo_ape bag2 replay.mcap /ground_truth /align_node/odometry -a` = the ATE in summary.json.

    Same definition: positions matched by stamp, SE(3) Umeyama alignment (-a/--align, no scale) of the estimate
    onto the ground truth, RMSE of the translation part (evo's default -r trans_part).
    """
    import subprocess
    import zipfile

    exe = _evo_ape()
    home = tmp_path / "home"  # evo writes its settings into ~/.evo on the first run
    home.mkdir()
    env = {**os.environ, "HOME": str(home), "MPLBACKEND": "Agg"}
    results = {}
    for flags in (["-a"], ["--align_origin"]):
        zipped = tmp_path / f"ape{len(results)}.zip"
        done = subprocess.run([str(exe), "bag2", str(live_replay / "replay.mcap"), "/ground_truth",
                               "/align_node/odometry", *flags, "--save_results", str(zipped), "--no_warnings"],
                              env=env, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stdout + done.stderr
        assert "rmse" in done.stdout
        with zipfile.ZipFile(zipped) as z:
            results[flags[0]] = json.loads(z.read("stats.json"))["rmse"]
    ate = json.loads((live_replay / "summary.json").read_text())["accuracy"]["ate"]["rmse_m"]
    assert results["-a"] == pytest.approx(ate, abs=1e-6)
    # Aligning the first poses only is another metric (the synthetic ground truth does not start at the origin).
    assert results["--align_origin"] > ate
