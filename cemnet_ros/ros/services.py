"""The node's services and ``~/set_pose``: each converts its request and hands it to the AlignerSession."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.node import Node
from std_srvs.srv import Trigger

from cemnet_ros.runtime.aligner_session import AlignerSession
from cemnet_ros.runtime.extrinsic import pose_msg_to_matrix


class NodeServices:
    """``~/reset``, ``~/relocalize``, ``~/save_map`` and the ``~/set_pose`` subscription (executor thread)."""

    def __init__(self, node: Node, session: AlignerSession, odom_frame: str,
                 warn: Callable[[str, str], None]) -> None:
        self._node, self._session, self._odom_frame, self._warn = node, session, odom_frame, warn
        self._set_pose = node.create_subscription(PoseWithCovarianceStamped, "~/set_pose", self._on_set_pose, 10)
        self._services = [node.create_service(Trigger, "~/reset", self._on_reset),
                          node.create_service(Trigger, "~/relocalize", self._on_relocalize),
                          node.create_service(Trigger, "~/save_map", self._on_save_map)]

    def destroy(self) -> None:
        """Destroy the services and the subscription (a lifecycle node's deactivate)."""
        self._node.destroy_subscription(self._set_pose)
        for service in self._services:
            self._node.destroy_service(service)

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        return self._request("reset", response, "reset: the map and motion model restart at the next scan; "
                             "the pose is kept (odom stays continuous)")

    def _on_relocalize(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        return self._request("relocalize", response,
                             "relocalize: the next scan runs the global search against the local map")

    def _request(self, name: str, response: Trigger.Response, message: str) -> Trigger.Response:
        self._session.request(name)
        self._node.get_logger().info(message)
        response.success, response.message = True, message
        return response

    def _on_set_pose(self, msg: PoseWithCovarianceStamped) -> None:
        frame = msg.header.frame_id
        if frame and frame != self._odom_frame:
            self._warn("set_pose", f"set_pose ignored: given in {frame!r}, not in {self._odom_frame!r}")
            return
        try:
            T_odom_base = pose_msg_to_matrix(msg.pose.pose)
        except ValueError as exc:
            self._warn("set_pose", f"set_pose ignored: {exc}")
            return
        self._session.set_pose(T_odom_base)
        x, y, z = T_odom_base[:3, 3]
        self._node.get_logger().info(f"set_pose: the next scan starts a new map at x={x:.3f} y={y:.3f} z={z:.3f} "
                                     f"in {self._odom_frame} (a deliberate jump)")

    def _on_save_map(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        points = self._session.map_in_odom()
        if points is None:
            response.success, response.message = False, "no map yet"
            return response
        from cemnet_ros.io.pointcloud_files import write_ply

        path = Path(f"cemnet_map_{time.strftime('%Y%m%d_%H%M%S')}.ply").resolve()
        write_ply(path, points)
        response.success = True
        response.message = f"wrote {len(points)} map points ({self._odom_frame}) to {path}"
        self._node.get_logger().info(response.message)
        return response
