"""Scan pipeline between sensor messages and the CEMNet core (no ROS imports here).

- ``aligner``: the recipe (:class:`~cemnet_ros.pipeline.aligner.ScanAligner`: check, preprocess, predict, track,
  judge, recover, commit); ``pair_mode`` the same steps against a target cloud; ``config`` the typed schema.
- ``steps/``: one module per step of the recipe (:mod:`cemnet_ros.pipeline.steps` lists them).
- ``map/``: the local voxel map that tracking registers against, and its numba kernels.

The node that drives it: :mod:`cemnet_ros.runtime` (threads, session, outputs, status; no ROS) under
:mod:`cemnet_ros.ros` (rclpy).

Import from the modules; these packages stay import-light (no torch) for the ROS layer and tests.
"""
