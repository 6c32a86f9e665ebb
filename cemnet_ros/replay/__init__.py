"""Offline replay of rosbag2 bags through the scan pipeline, and trajectory metrics against ground truth."""
