"""The steps of the recipe that :class:`~cemnet_ros.pipeline.aligner.ScanAligner` runs on each scan, one module each.

**check** ``input_checks``; **preprocess** ``frame`` (units, the frame's subsets), ``preprocess`` (crop, voxel
grid, subsets), ``sweep`` and ``deskew`` (motion compensation); **predict** ``motion`` (constant velocity) and
``adaptive`` (how far to search); **register** ``registration`` (the plan run until the decision settles),
``starts`` (the plan: prediction, CEM, last pose, global search, turns, neighbours), ``contest`` (each start
polished once), ``polish`` (fine, basin, wide: ``refine`` the point-to-plane ICP, ``basin`` the GICP stage) and
``metric_cem`` (the CEM and the global search in metres); **decide** ``answer`` (what one answer measures),
``evidence`` (the record the decision reads), ``decision`` (the rules and the outcomes), ``health`` (signals, the
running level) and ``covariance`` (from the polish's Hessian); **commit** ``alignment_step`` (what a scan
returns) and ``lost_streak`` (where a lost map restarts). Import from the modules; this package stays
import-light (no torch: ``metric_cem`` imports it, the ROS layer does not).
"""
