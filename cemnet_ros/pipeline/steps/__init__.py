"""The steps of the recipe that :class:`~cemnet_ros.pipeline.aligner.ScanAligner` runs on each scan, one module each.

**check** ``input_checks``; **preprocess** ``frame`` (units, the frame's subsets), ``preprocess`` (crop, voxel
grid, subsets), ``sweep`` and ``deskew`` (motion compensation); **predict** ``motion`` (constant velocity) and
``adaptive`` (how far to search); **track** ``tracking`` (the CEM, then the polish: ``basin`` its wide GICP stage,
``refine`` the point-to-plane ICP); **judge** ``verdict``, ``health`` (failure signals), ``covariance`` (from the
polish's Hessian) and ``contest`` (competing answers); **recover** ``recovery`` (the global search);
``track_then_recover`` registers a frame (track, then recover when tracking doubts its answer). Import
from the modules; this package stays import-light (no torch: ``recovery`` imports it, the ROS layer does not).
"""
