"""The pose/odometry/TF fillers shared by align_node (rclpy classes) and the bag writer (rosbags classes)."""
from __future__ import annotations

import numpy as np
import pytest

from cemnet_ros import pose_messages
from cemnet_ros.replay.bag_types import TYPESTORE, rosbags_type
from cemnet_ros.runtime.extrinsic import pose_from_xyz_rpy, pose_msg_to_matrix, transform_msg_to_matrix
from cemnet_ros.runtime.odometry_output import UNKNOWN_VARIANCE

T = pose_from_xyz_rpy((1.5, -2.0, 0.25, 0.1, -0.2, 2.5))
COV = np.diag([1e-4, 2e-4, 3e-4, 1e-5, 2e-5, 3e-5]) + 1e-7


def _numbers(msg):
    """Every number of an Odometry message, in a fixed order."""
    t = msg.twist.twist
    return np.concatenate([pose_msg_to_matrix(msg.pose.pose).ravel(), msg.pose.covariance, msg.twist.covariance,
                           [t.linear.x, t.linear.y, t.linear.z, t.angular.x, t.angular.y, t.angular.z]])


def _odometry(types, **twist):
    head = pose_messages.header(types, "odom", pose_messages.stamp(types, 1_500_000_007))
    return pose_messages.odometry(types, head, "base_link", T, COV, **twist)


def test_stamps_split_nanoseconds_and_refuse_negative_ones():
    stamp = pose_messages.stamp(rosbags_type, 12 * 10 ** 9 + 345)
    assert (stamp.sec, stamp.nanosec) == (12, 345)
    with pytest.raises(ValueError):
        pose_messages.stamp(rosbags_type, -1)


def test_pose_and_transform_give_back_the_matrix():
    head = pose_messages.header(rosbags_type, "odom", pose_messages.stamp(rosbags_type, 5))
    np.testing.assert_allclose(pose_msg_to_matrix(pose_messages.pose_stamped(rosbags_type, head, T).pose), T,
                               atol=1e-12)
    tf = pose_messages.tf_message(rosbags_type, head, "base_link", T).transforms[0]
    assert tf.header.frame_id == "odom" and tf.child_frame_id == "base_link" and tf.header.stamp.nanosec == 5
    np.testing.assert_allclose(transform_msg_to_matrix(tf.transform), T, atol=1e-12)


def test_odometry_carries_its_covariances_and_an_unknown_twist_is_huge():
    known = _odometry(rosbags_type, linear=np.array([1.0, 2, 3]), angular=np.array([0.1, 0.2, 0.3]),
                      twist_covariance=COV * 4)
    np.testing.assert_array_equal(np.reshape(known.pose.covariance, (6, 6)), COV)
    np.testing.assert_array_equal(np.reshape(known.twist.covariance, (6, 6)), COV * 4)
    assert (known.twist.twist.linear.z, known.twist.twist.angular.x) == (3.0, 0.1)
    unknown = _odometry(rosbags_type, linear=np.array([1.0, 2, 3]))  # no twist covariance: nothing measured
    assert unknown.twist.twist.linear.x == 0.0
    np.testing.assert_array_equal(np.reshape(unknown.twist.covariance, (6, 6)), np.eye(6) * UNKNOWN_VARIANCE)


def test_the_rosbags_messages_serialize():
    msg = _odometry(rosbags_type, linear=np.ones(3), angular=np.ones(3), twist_covariance=COV)
    raw = TYPESTORE.serialize_cdr(msg, "nav_msgs/msg/Odometry")
    np.testing.assert_array_equal(_numbers(TYPESTORE.deserialize_cdr(raw, "nav_msgs/msg/Odometry")), _numbers(msg))


def test_rclpy_and_rosbags_messages_carry_the_same_numbers():
    pytest.importorskip("nav_msgs.msg", reason="rclpy message packages not installed (no ROS)")
    from cemnet_ros.ros.messages import rclpy_type

    twist = dict(linear=np.array([0.5, -0.1, 0.0]), angular=np.array([0.0, 0.0, 0.2]), twist_covariance=COV * 9)
    live, replayed = _odometry(rclpy_type, **twist), _odometry(rosbags_type, **twist)
    assert type(live).__module__.startswith("nav_msgs") and live.header.stamp.nanosec == 500_000_007
    np.testing.assert_array_equal(_numbers(live), _numbers(replayed))
    assert live.child_frame_id == replayed.child_frame_id == "base_link"
