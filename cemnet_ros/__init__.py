"""cemnet_ros: CEMNet point cloud registration with a ROS 2 front end.

The algorithm lives in :mod:`cemnet_ros.core` (torch/numpy, never rclpy); the ROS layer in
:mod:`cemnet_ros.ros` only converts, queues and publishes.
"""

__version__ = "0.1.0"
