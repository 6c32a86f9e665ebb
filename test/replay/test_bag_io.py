"""rosbag2 I/O: write tiny bags with rosbags and read them back; clear errors for bad bags."""
from __future__ import annotations

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from scipy.spatial.transform import Rotation

from cemnet_ros.replay.bag_io import TYPESTORE, BagError, BagReader, BagWriter, ns_to_stamp

STAMP0 = 1_700_000_000_000_000_000


def _pose(yaw: float, t) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = Rotation.from_euler("z", yaw).as_matrix()
    out[:3, 3] = t
    return out


def _write_small(path, n=3, with_gt=True):
    rng = np.random.default_rng(0)
    clouds = [rng.normal(size=(100 + i, 3)) for i in range(n)]
    poses = [_pose(0.1 * i, (i, 0.5 * i, 0)) for i in range(n)]
    with BagWriter(path) as bag:
        for i in range(n):
            stamp = STAMP0 + i * 100_000_000
            bag.write_cloud("/points", clouds[i], "lidar", stamp)
            if with_gt:
                bag.write_pose("/ground_truth", poses[i], "world", stamp)
    return clouds, poses


def test_write_then_read_back(tmp_path):
    path = tmp_path / "small.mcap"
    clouds, poses = _write_small(path)
    assert path.is_file()
    assert [p.name for p in tmp_path.iterdir()] == ["small.mcap"]  # the temporary directory is gone
    with BagReader(path) as reader:
        assert reader.info.cloud_topic == "/points"
        assert reader.info.gt_topic == "/ground_truth"
        assert reader.info.n_clouds == 3 and reader.info.n_gt == 3
        frames = list(reader.clouds())
        stamps, gt, frame = reader.ground_truth()
        assert [f.stamp_ns for f in reader.clouds(limit=2)] == [STAMP0, STAMP0 + 100_000_000]
    assert frame == "world"
    assert [f.frame_id for f in frames] == ["lidar"] * 3
    for f, c in zip(frames, clouds):
        np.testing.assert_allclose(f.points, c.astype(np.float32), atol=0)  # float32 on the wire
    assert stamps.tolist() == [STAMP0 + i * 100_000_000 for i in range(3)]
    np.testing.assert_allclose(gt, np.stack(poses), atol=1e-12)


def test_odometry_and_overwrite(tmp_path):
    path = tmp_path / "odom.mcap"
    cov = np.diag([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    with BagWriter(path) as bag:
        bag.write_odometry("/odom", _pose(0.2, (1, 2, 3)), cov, "odom", "base", STAMP0)
    with pytest.raises(FileExistsError):
        BagWriter(path)
    with BagWriter(path, overwrite=True) as bag:  # replaced atomically
        bag.write_odometry("/odom", _pose(0.3, (1, 2, 3)), cov, "odom", "base", STAMP0)
        bag.write_cloud("/c", np.ones((5, 3)), "odom", STAMP0)
    with pytest.raises(BagError, match="not sensor_msgs/msg/PointCloud2"):
        BagReader(path, topic="/odom")
    with BagReader(path, gt_topic="/odom") as reader:  # Odometry works as ground truth too
        stamps, poses, frame = reader.ground_truth()
    assert frame == "odom" and len(poses) == 1
    np.testing.assert_allclose(poses[0], _pose(0.3, (1, 2, 3)), atol=1e-12)
    with AnyReader([path]) as raw:
        (conn,) = [c for c in raw.connections if c.topic == "/odom"]
        msg = raw.deserialize(next(raw.messages([conn]))[2], conn.msgtype)
    assert msg.child_frame_id == "base"
    np.testing.assert_allclose(np.asarray(msg.pose.covariance).reshape(6, 6), cov)


def test_failed_write_leaves_nothing(tmp_path):
    path = tmp_path / "broken.mcap"
    with pytest.raises(RuntimeError, match="boom"):
        with BagWriter(path) as bag:
            bag.write_cloud("/points", np.zeros((4, 3)), "lidar", STAMP0)
            raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


def test_reads_rosbag2_directory_sqlite3(tmp_path):
    """A classic rosbag2 directory (sqlite3 storage, metadata.yaml) written with rosbags' own Writer."""
    from cemnet_ros.pointcloud2 import make_pointcloud2

    types = TYPESTORE.types
    bagdir = tmp_path / "dirbag"
    writer = Writer(bagdir, version=9, storage_plugin=StoragePlugin.SQLITE3)
    writer.open()
    conn = writer.add_connection("/velodyne_points", "sensor_msgs/msg/PointCloud2", typestore=TYPESTORE)
    for i in range(2):
        msg = make_pointcloud2(types["sensor_msgs/msg/PointCloud2"], types["sensor_msgs/msg/PointField"],
                               np.full((10, 3), float(i + 1)), "velodyne", ns_to_stamp(STAMP0 + i),
                               header_cls=types["std_msgs/msg/Header"])
        writer.write(conn, STAMP0 + i, TYPESTORE.serialize_cdr(msg, "sensor_msgs/msg/PointCloud2"))
    writer.close()
    with BagReader(bagdir) as reader:
        assert reader.info.cloud_topic == "/velodyne_points" and reader.info.gt_topic is None
        frames = list(reader.clouds())
        stamps, poses, _ = reader.ground_truth()
    assert len(frames) == 2 and frames[1].points[0, 0] == 2.0
    assert len(stamps) == 0 and poses.shape == (0, 4, 4)


def test_missing_bag(tmp_path):
    with pytest.raises(BagError, match="not found"):
        BagReader(tmp_path / "nope.mcap")


@pytest.mark.parametrize("content", [b"", b"this is not an mcap file at all" * 10])
def test_corrupt_bag(tmp_path, content):
    path = tmp_path / "corrupt.mcap"
    path.write_bytes(content)
    with pytest.raises(BagError, match="corrupt|cannot"):
        with BagReader(path) as reader:
            list(reader.clouds())


def test_truncated_bag(tmp_path):
    path = tmp_path / "whole.mcap"
    _write_small(path, n=5)
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(BagError):
        with BagReader(cut) as reader:
            list(reader.clouds())


def test_unknown_storage_and_empty_directory(tmp_path):
    other = tmp_path / "scan.bin"
    other.write_bytes(b"\0" * 64)
    with pytest.raises(BagError, match="cannot open"):
        BagReader(other)
    (tmp_path / "emptydir").mkdir()
    with pytest.raises(BagError, match="cannot open"):
        BagReader(tmp_path / "emptydir")


def test_topic_errors(tmp_path):
    path = tmp_path / "two.mcap"
    with BagWriter(path) as bag:
        bag.write_cloud("/a", np.zeros((4, 3)), "s", STAMP0)
        bag.write_cloud("/b", np.zeros((4, 3)), "s", STAMP0)
        bag.write_pose("/pose", np.eye(4), "world", STAMP0)
    with pytest.raises(BagError, match="several PointCloud2 topics"):
        BagReader(path)
    with pytest.raises(BagError, match="not in"):
        BagReader(path, topic="/missing")
    with pytest.raises(BagError, match="not sensor_msgs/msg/PointCloud2"):
        BagReader(path, topic="/pose")
    with pytest.raises(BagError, match="ground-truth topic /nope"):
        BagReader(path, topic="/a", gt_topic="/nope")
    with pytest.raises(BagError, match="expected one of"):
        BagReader(path, topic="/a", gt_topic="/b")
    with BagReader(path, topic="/b", gt_topic="/pose") as reader:
        assert reader.info.n_clouds == 1 and reader.info.n_gt == 1
    no_cloud = tmp_path / "nocloud.mcap"
    with BagWriter(no_cloud) as bag:
        bag.write_pose("/pose", np.eye(4), "world", STAMP0)
    with pytest.raises(BagError, match="no sensor_msgs/msg/PointCloud2 topic"):
        BagReader(no_cloud)


def test_undecodable_cloud_names_the_message(tmp_path):
    path = tmp_path / "nan.mcap"
    with BagWriter(path) as bag:
        bag.write_cloud("/points", np.ones((4, 3)), "s", STAMP0)
        bag.write_cloud("/points", np.full((4, 3), np.nan), "s", STAMP0 + 1)
    with BagReader(path) as reader:
        with pytest.raises(BagError, match="message 1: .*no finite point"):
            list(reader.clouds())


def test_odometry_twist_and_transform_messages(tmp_path):
    """What the replay writes for align_node's outputs: Odometry with twist + covariances, TFMessage."""
    from cemnet_ros.replay.bag_io import UNKNOWN_VARIANCE

    path = tmp_path / "live.mcap"
    cov, twist_cov = np.diag([1.0, 2, 3, 4, 5, 6]), np.diag([7.0, 8, 9, 10, 11, 12])
    T = _pose(0.4, (1, -2, 0.5))
    with BagWriter(path) as bag:
        bag.write_odometry("/odom", T, cov, "odom", "base_link", STAMP0)  # the first step: twist unknown
        bag.write_odometry("/odom", T, cov, "odom", "base_link", STAMP0 + 1, linear=(1.0, 2.0, 3.0),
                           angular=np.array([0.1, 0.2, 0.3]), twist_covariance=twist_cov)
        bag.write_transform("/tf", T, "odom", "base_link", STAMP0)
    with AnyReader([path]) as raw:
        msgs = {c.topic: [raw.deserialize(r, c.msgtype) for _, _, r in raw.messages([c])] for c in raw.connections}
        types = {c.topic: c.msgtype for c in raw.connections}
    assert types == {"/odom": "nav_msgs/msg/Odometry", "/tf": "tf2_msgs/msg/TFMessage"}
    first, second = msgs["/odom"]
    t = first.twist.twist
    assert [t.linear.x, t.linear.y, t.linear.z, t.angular.x, t.angular.y, t.angular.z] == [0.0] * 6
    np.testing.assert_array_equal(np.reshape(first.twist.covariance, (6, 6)), np.eye(6) * UNKNOWN_VARIANCE)
    t = second.twist.twist
    np.testing.assert_allclose([t.linear.x, t.linear.y, t.linear.z, t.angular.x, t.angular.y, t.angular.z],
                               [1, 2, 3, 0.1, 0.2, 0.3])
    np.testing.assert_array_equal(np.reshape(second.twist.covariance, (6, 6)), twist_cov)
    np.testing.assert_array_equal(np.reshape(second.pose.covariance, (6, 6)), cov)
    (tf,) = msgs["/tf"][0].transforms
    assert (tf.header.frame_id, tf.child_frame_id) == ("odom", "base_link")
    assert (tf.header.stamp.sec, tf.header.stamp.nanosec) == divmod(STAMP0, 1_000_000_000)
    q, p = tf.transform.rotation, tf.transform.translation
    back = np.eye(4)
    back[:3, :3], back[:3, 3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix(), [p.x, p.y, p.z]
    np.testing.assert_allclose(back, T, atol=1e-12)


def test_messages_copy_unchanged(tmp_path):
    """BagReader.messages + BagWriter.write_message: same topic, type, header, content and bag time."""
    src, dst = tmp_path / "src.mcap", tmp_path / "dst.mcap"
    with BagWriter(src) as bag:
        for i, pose in enumerate([_pose(0.1 * i, (i, 0, 0)) for i in range(3)]):
            bag.write_cloud("/points", np.ones((5, 3)), "lidar", STAMP0 + i)
            bag.write_pose("/ground_truth", pose, "world", STAMP0 + i)
        bag.write_transform("/tf_static", _pose(0.0, (0, 0, 1.5)), "base_link", "lidar", STAMP0)
    with BagReader(src) as reader:
        copied = [(topic, *m) for topic in ("/ground_truth", "/tf_static", "/absent") for m in reader.messages(topic)]
        with BagWriter(dst) as bag:
            for topic, bag_ns, msgtype, msg in copied:
                bag.write_message(topic, msgtype, msg, bag_ns)
    with AnyReader([src]) as a, AnyReader([dst]) as b:
        def dump(reader):
            return sorted((c.topic, c.msgtype, t, bytes(r)) for c, t, r in reader.messages()
                          if c.topic != "/points")
        assert dump(a) == dump(b) and len(dump(b)) == 4  # byte for byte
