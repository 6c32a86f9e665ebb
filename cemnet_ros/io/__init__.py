"""File input/output that the tools and tests share (point cloud files, atomic writes)."""
from cemnet_ros.io.atomic import atomic_write_bytes, atomic_write_text
from cemnet_ros.io.pointcloud_files import read_points, write_ply

__all__ = ["read_points", "write_ply", "atomic_write_bytes", "atomic_write_text"]
