"""The node's runtime around the scan pipeline, as plain code (no ROS imports): what ``align_node``
(:mod:`cemnet_ros.ros`) and the replay share.

``aligner_session`` (loading the aligner in the background, service requests between scans, the map lock),
``worker`` (the bounded queue and its thread), ``pairing`` (pair mode's matching of sources to targets by stamp),
``scan_status`` (each input's verdict and log lines), ``node_status`` (the diagnostics), ``odometry_output`` (the
numbers published for a step) and ``extrinsic`` (the base frame: from the sensor's odometry to the robot's).
Import from the modules; this package stays import-light (no torch: the node subscribes before the engine loads).
"""
