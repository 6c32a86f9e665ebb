"""``~/path``: the published poses as a nav_msgs/Path, for RViz (``path_period`` > 0).

The worker adds each ``~/pose`` message as it is published (no second conversion); a timer publishes the newest
``path_max_poses`` of them every ``path_period`` seconds while someone subscribes and a pose was added since the
last one. RELIABLE + TRANSIENT_LOCAL, depth 1: a display that starts later gets the last path at once.
"""
from __future__ import annotations

import collections
import threading
from typing import Any

from nav_msgs.msg import Path
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy


class PathOutput:
    """A bounded window of PoseStamped messages and its publisher."""

    def __init__(self, node: Node, max_poses: int) -> None:
        self._node = node
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._publisher = node.create_publisher(Path, "~/path", latched)
        self._poses: collections.deque = collections.deque(maxlen=max_poses)
        self._lock = threading.Lock()
        self._added = False  # a pose came since the last publication

    def add(self, pose_stamped: Any) -> None:
        """One published pose (worker thread)."""
        with self._lock:
            self._poses.append(pose_stamped)
            self._added = True

    def publish(self) -> None:
        """The window as a Path in the newest pose's frame and stamp (timer thread); nothing when no pose came
        since the last publication or nobody subscribes."""
        if self._publisher.get_subscription_count() == 0:
            return
        with self._lock:
            if not self._added:
                return
            poses, self._added = list(self._poses), False
        self._publisher.publish(Path(header=poses[-1].header, poses=poses))

    def destroy(self) -> None:
        self._node.destroy_publisher(self._publisher)
