"""The steps of the recipe that :class:`~cemnet_ros.pipeline.aligner.ScanAligner` runs on each scan, one module each.

**check** ``input_checks``; **preprocess** ``frame`` (units, the frame's subsets), ``preprocess`` (crop, voxel
grid, subsets), ``sweep`` and ``deskew`` (motion compensation); **predict** ``motion`` (constant velocity) and
``adaptive`` (how far to search); **track** ``tracking`` (the order of the starts), ``contest`` (polish a start,
judge it, does it stand, choose), ``polish`` (fine, basin, wide: ``refine`` the point-to-plane ICP, ``basin`` the
GICP stage) and ``metric_cem`` (the engine in metres); **judge** ``verdict``, ``health`` (failure signals) and
``covariance`` (from the polish's Hessian); **recover** ``recovery`` (the global search); **commit**
``lost_streak`` (where a lost map restarts);
``track_then_recover`` registers a frame (track, then recover when tracking doubts its answer). Import
from the modules; this package stays import-light (no torch: ``recovery`` imports it, the ROS layer does not).
"""
