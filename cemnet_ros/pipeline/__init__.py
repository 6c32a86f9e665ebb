"""Scan pipeline between sensor messages and the CEMNet core (no ROS imports here).

Modules: ``config`` (the typed schema), ``preprocess`` (crop, voxel grid, subsets), ``voxel_map`` (the local
map), ``refine`` (point-to-plane polish), ``motion`` (constant velocity), ``adaptive`` (search spread),
``health`` (failure signals), ``covariance`` (from the polish's Hessian), ``aligner``
(:class:`~cemnet_ros.pipeline.aligner.ScanAligner`, the recipe) and ``worker`` (bounded queue + thread).
Import from the modules; this package stays import-light (no torch) for the ROS layer and tests.
"""
