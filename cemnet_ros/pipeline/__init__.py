"""Scan pipeline between sensor messages and the CEMNet core (no ROS imports here).

Modules: ``preprocess`` (crop, voxel grid, subset), ``motion`` (constant velocity), ``covariance`` (from the
CEM spread), ``aligner`` (:class:`~cemnet_ros.pipeline.aligner.ScanAligner`) and ``worker`` (bounded queue +
thread). Import from the modules; this package stays import-light (no torch) for the ROS layer and tests.
"""
