"""ROS 2 (rclpy) front end of cemnet_ros: the ``align_node`` executable."""
