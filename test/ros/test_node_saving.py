"""~/save_map, ~/save_trajectory and ~/path on a running align_node over DDS (localhost, a random domain): the
files read back with the repo's readers, an independent one where installed, and numpy, against what the node
published; the save paths changed at runtime through the parameter service, as ``ros2 param set`` does."""
from __future__ import annotations

import os

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # read when the DDS participant is created

from diagnostic_msgs.msg import DiagnosticStatus  # noqa: E402
from nav_msgs.msg import Path  # noqa: E402
from node_harness import FIRST_TIMEOUT, POSES, pose_of, scan_msg, wait_for  # noqa: E402
from rcl_interfaces.srv import SetParameters  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from cemnet_ros.io.pointcloud_files import read_points  # noqa: E402

pytestmark = pytest.mark.dds
SCANS = 4


def _call(h, service: str, timeout: float = 20.0) -> Trigger.Response:
    client = h.probe.create_client(Trigger, f"/{h.namespace}/align_node/{service}")
    assert client.wait_for_service(timeout_sec=5), service
    future = client.call_async(Trigger.Request())
    assert wait_for(future.done, timeout), f"{service} did not answer"
    return future.result()


def _set(h, name: str, value: str):
    """What ``ros2 param set /<ns>/align_node <name> <value>`` does: the node's SetParameters service."""
    client = h.probe.create_client(SetParameters, f"/{h.namespace}/align_node/set_parameters")
    assert client.wait_for_service(timeout_sec=5)
    future = client.call_async(SetParameters.Request(parameters=[Parameter(name, value=value).to_parameter_msg()]))
    assert wait_for(future.done, 10)
    return future.result().results[0]


def _stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def _drive(h) -> list:
    """SCANS scans through the node; their odometry, and every verdict on ~/scan_status."""
    outputs = [h.send(scan_msg(k), timeout=FIRST_TIMEOUT if k < 2 else 60.0) for k in range(SCANS)]
    assert wait_for(lambda: len(h.statuses) >= SCANS, 10)
    return outputs


def test_the_map_and_the_trajectory_are_saved_where_the_parameters_say(harness_factory, tmp_path):
    h = harness_factory({"save_directory": str(tmp_path)})
    assert _call(h, "save_trajectory").message == "no trajectory yet: no scan has been processed"
    outputs = _drive(h)

    # The map, with the defaults: a timestamped binary PCD in save_directory, in odom, as the node holds it.
    answer = _call(h, "save_map")
    (saved,) = tmp_path.glob("cemnet_map_*.pcd")
    assert answer.success and answer.message.endswith(f"map points (odom) to {saved}"), answer.message
    expected = h.node._session.map_in_odom().astype(np.float32)
    assert len(expected) > 1000
    np.testing.assert_array_equal(read_points(saved), expected)
    try:
        from pypcd4 import PointCloud
    except ImportError:
        pass  # the independent reader is optional (test/io/test_pointcloud_files.py skips without it)
    else:
        np.testing.assert_array_equal(PointCloud.from_path(saved).numpy(("x", "y", "z")), expected)

    # A path set at runtime: PLY in a folder that does not exist yet.
    assert _set(h, "save_map_path", "maps/run1.ply").successful
    answer = _call(h, "save_map")
    assert answer.success and (tmp_path / "maps" / "run1.ply").read_bytes().startswith(b"ply\n"), answer.message
    np.testing.assert_array_equal(read_points(tmp_path / "maps" / "run1.ply"), expected)

    # The trajectory as TUM: every published pose, parsed with numpy against the odometry received.
    answer = _call(h, "save_trajectory")
    (tum,) = tmp_path.glob("cemnet_trajectory_*.tum")
    assert answer.success and f"wrote {SCANS} poses of base_link in odom" in answer.message, answer.message
    assert tum.read_text().startswith("# timestamp tx ty tz qx qy qz qw\n")
    table = np.loadtxt(tum, skiprows=1, dtype=str)
    stamps = [int(sec) * 1_000_000_000 + int(frac) for sec, frac in (s.split(".") for s in table[:, 0])]
    assert stamps == [_stamp_ns(o) for o in outputs]
    values = table[:, 1:].astype(float)
    published = np.array([pose_of(o) for o in outputs])
    np.testing.assert_allclose(values[:, :3], published[:, :3, 3], atol=1e-8)
    np.testing.assert_allclose(Rotation.from_quat(values[:, 3:]).as_matrix(), published[:, :3, :3], atol=1e-8)
    assert np.linalg.norm(published[-1][:3, 3] - published[0][:3, 3]) > 1.0  # the base moved (0.5 m a scan)
    flags = np.loadtxt(tum.with_suffix(".flags.csv"), delimiter=",", skiprows=1, dtype=str)
    verdicts = {int(s.name): s.level == DiagnosticStatus.OK for s in h.statuses}
    assert [row[1] == "1" for row in flags] == [verdicts[s] for s in stamps]

    # KITTI, set at runtime: 12 numbers a line, the 3x4 of each published pose.
    assert _set(h, "save_trajectory_path", "odom.kitti").successful
    assert _call(h, "save_trajectory").success
    np.testing.assert_allclose(np.loadtxt(tmp_path / "odom.kitti").reshape(-1, 3, 4), published[:, :3, :],
                               atol=1e-8)

    # Failures are answers, not exceptions: an unknown suffix, a folder that is a file.
    assert _set(h, "save_map_path", "map.xyz").successful
    answer = _call(h, "save_map")
    assert not answer.success and "unknown map suffix '.xyz'" in answer.message
    assert _set(h, "save_directory", str(tum)).successful
    answer = _call(h, "save_trajectory")
    assert not answer.success and f"{tum} is a file, not a folder" in answer.message, answer.message
    assert not _set(h, "input_topic", "other").successful  # the others stay read-only

    # The diagnostics name the sensor: the scans' frame on the resolved input topic.
    assert wait_for(lambda: h.diagnostics and h.diagnostics[-1].hardware_id == f"lidar on /{h.namespace}/points",
                    5), h.diagnostics[-1].hardware_id
    assert h.statuses[-1].hardware_id == f"lidar on /{h.namespace}/points"


def test_path_publishes_the_newest_poses_at_its_period(harness_factory):
    h = harness_factory({"path_period": 0.2, "path_max_poses": 3})
    paths = []
    h.probe.create_subscription(Path, f"/{h.namespace}/align_node/path", paths.append,
                                QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                           durability=DurabilityPolicy.TRANSIENT_LOCAL))
    outputs = _drive(h)
    assert wait_for(lambda: paths and _stamp_ns(paths[-1]) == _stamp_ns(outputs[-1]), 10)
    path = paths[-1]
    assert path.header.frame_id == "odom" and len(path.poses) == 3  # bounded: the newest path_max_poses
    assert [_stamp_ns(p) for p in path.poses] == [_stamp_ns(o) for o in outputs[-3:]]
    for pose, odom in zip(path.poses, outputs[-3:]):
        np.testing.assert_allclose(pose_of(pose), pose_of(odom), atol=1e-9)
    count = len(paths)
    assert not wait_for(lambda: len(paths) > count, 1.0)  # no new pose: not published again
    h.send(scan_msg(SCANS, pose=POSES[SCANS]))
    assert wait_for(lambda: len(paths) > count, 5)


def test_path_is_off_by_default(harness_factory):
    h = harness_factory()
    h.send(scan_msg(0), timeout=FIRST_TIMEOUT)
    names = dict(h.probe.get_topic_names_and_types())
    assert f"/{h.namespace}/align_node/pose" in names and f"/{h.namespace}/align_node/path" not in names
