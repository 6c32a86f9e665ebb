"""Filling the node's output messages from a step's base-frame pose, motion and covariance."""
from __future__ import annotations

from typing import Any

import numpy as np
from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import Odometry
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import PointCloud2

from cemnet_ros.pipeline.odometry_output import OdometryOutput
from cemnet_ros.pointcloud2 import as_bytes


def fill_pose(pose_msg: Any, T: np.ndarray) -> None:
    """geometry_msgs/Pose from a 4x4 transform."""
    pose_msg.position.x, pose_msg.position.y, pose_msg.position.z = (float(v) for v in T[:3, 3])
    qx, qy, qz, qw = Rotation.from_matrix(T[:3, :3]).as_quat()
    pose_msg.orientation.x, pose_msg.orientation.y = float(qx), float(qy)
    pose_msg.orientation.z, pose_msg.orientation.w = float(qz), float(qw)


def odometry(header: Any, child_frame: str, out: OdometryOutput) -> Odometry:
    """nav_msgs/Odometry of one step: the pose in the header's frame, the twist in ``child_frame`` (REP-105)."""
    msg = Odometry()
    msg.header = header
    msg.child_frame_id = child_frame
    fill_pose(msg.pose.pose, out.T_odom_base)
    msg.pose.covariance = [float(v) for v in out.pose_covariance.reshape(-1)]
    t = msg.twist.twist
    t.linear.x, t.linear.y, t.linear.z = (float(v) for v in out.linear)
    t.angular.x, t.angular.y, t.angular.z = (float(v) for v in out.angular)
    msg.twist.covariance = [float(v) for v in out.twist_covariance.reshape(-1)]
    return msg


def transform(header: Any, child_frame: str, T_parent_child: np.ndarray) -> TransformStamped:
    """geometry_msgs/TransformStamped of ``child_frame`` in the header's frame."""
    msg = TransformStamped()
    msg.header = header
    msg.child_frame_id = child_frame
    msg.transform.translation.x, msg.transform.translation.y, msg.transform.translation.z = (
        float(v) for v in T_parent_child[:3, 3])
    q = Rotation.from_matrix(T_parent_child[:3, :3]).as_quat()
    msg.transform.rotation.x, msg.transform.rotation.y = float(q[0]), float(q[1])
    msg.transform.rotation.z, msg.transform.rotation.w = float(q[2]), float(q[3])
    return msg


def transformed_cloud(cloud: PointCloud2, T: np.ndarray, frame_id: str) -> PointCloud2:
    """A copy of ``cloud`` with x, y, z moved by ``T`` and every other field kept (float32/64 coordinates)."""
    data = as_bytes(cloud.data).copy()
    n, step, row = int(cloud.height) * int(cloud.width), int(cloud.point_step), int(cloud.row_step)
    endian = ">" if cloud.is_bigendian else "<"
    fields = {f.name: f for f in cloud.fields}
    views = []
    for name in "xyz":
        f = fields[name]
        dtype = np.dtype(endian + ("f4" if f.datatype == 7 else "f8"))
        views.append(np.ndarray((int(cloud.height), int(cloud.width)), dtype=dtype, buffer=data, offset=int(f.offset),
                                strides=(row, step)))
    xyz = np.stack([v.reshape(-1).astype(np.float64) for v in views], axis=1) if n else np.zeros((0, 3))
    moved = xyz @ T[:3, :3].T + T[:3, 3]
    for axis, view in enumerate(views):
        view[...] = moved[:, axis].reshape(view.shape)
    out = PointCloud2(height=cloud.height, width=cloud.width, fields=list(cloud.fields),
                      is_bigendian=cloud.is_bigendian, point_step=cloud.point_step, row_step=cloud.row_step,
                      data=data.tobytes(), is_dense=cloud.is_dense)
    out.header.stamp, out.header.frame_id = cloud.header.stamp, frame_id
    return out
