"""The node's services and ``~/set_pose``: each converts its request and hands it to the AlignerSession (the
saving to runtime/saving.py, with the save parameters' values at the call: ``ros2 param set`` changes them)."""
from __future__ import annotations

from typing import Callable

from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.node import Node
from std_srvs.srv import Trigger

from cemnet_ros.ros.node_config import NodeConfig
from cemnet_ros.runtime.aligner_session import AlignerSession
from cemnet_ros.runtime.extrinsic import pose_msg_to_matrix
from cemnet_ros.runtime.saving import Saved, save_map, save_trajectory


class NodeServices:
    """``~/reset``, ``~/relocalize``, ``~/save_map``, ``~/save_trajectory`` and the ``~/set_pose`` subscription
    (executor thread)."""

    def __init__(self, node: Node, session: AlignerSession, cfg: NodeConfig,
                 warn: Callable[[str, str], None]) -> None:
        self._node, self._session, self._cfg, self._warn = node, session, cfg, warn
        self._odom_frame = cfg.odom_frame
        self._set_pose = node.create_subscription(PoseWithCovarianceStamped, "~/set_pose", self._on_set_pose, 10)
        self._services = [node.create_service(Trigger, "~/reset", self._on_reset),
                          node.create_service(Trigger, "~/relocalize", self._on_relocalize),
                          node.create_service(Trigger, "~/save_map", self._on_save_map),
                          node.create_service(Trigger, "~/save_trajectory", self._on_save_trajectory)]

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
        saved = save_map(self._session.map_in_odom(), self._parameter("save_map_path"),
                         self._parameter("save_directory"), self._odom_frame)
        return self._answer(saved, response)

    def _on_save_trajectory(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        frame = self._odom_frame if self._cfg.mode == "sequential" else "the target's frame"
        saved = save_trajectory(self._session.trajectory.snapshot(), self._parameter("save_trajectory_path"),
                                self._parameter("save_directory"), frame, self._cfg.base_frame)
        return self._answer(saved, response)

    def _parameter(self, name: str) -> str:
        """A save parameter's value now (they are settable at runtime)."""
        return str(self._node.get_parameter(name).value)

    def _answer(self, saved: Saved, response: Trigger.Response) -> Trigger.Response:
        if saved.success:  # one call site per severity: rclpy's logger refuses a site that changes it
            self._node.get_logger().info(saved.message)
        else:
            self._node.get_logger().warn(saved.message)
        response.success, response.message = saved.success, saved.message
        return response
