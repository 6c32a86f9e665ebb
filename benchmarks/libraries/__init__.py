"""The project's own classical point cloud code against the well-kept libraries, piece by piece:
the voxel grid, the local map, nearest map points, the point-to-plane polish and the start-up.

Peers, the ``bench`` extras, each optional (a missing one is left out with a message): small_gicp
(``voxelgrid_sampling``, ``IncrementalVoxelMap`` / ``GaussianVoxelMap``, ``KdTree``, ``estimate_normals`` /
``estimate_covariances``, ``align``) and KISS-ICP (``voxel_down_sample``, ``VoxelHashMap``, its point-to-point
registration); scipy's ``cKDTree`` (a core dependency) for the nearest points.

Every method gets the node's parameters (frame voxel, map voxel and points per voxel, the polish's stages:
points, pairing distance, iteration cap) and :data:`~.peers.THREADS` threads. Times are interleaved: a round
runs every method once in turn (A, B, C, A, B, C, ...), so that other load on the machine falls on all of them
alike; the ratio ours / method is taken per round and summarised by its median, also over the quiet rounds alone
(other processes below :data:`~.timing.QUIET_CORES`). Run it under the node's thread policy (``import
cemnet_ros.ros`` before numpy, as ``scripts/bench_libraries.py`` does): numba's and small_gicp's OpenMP pools
share the process, and spinning idle threads slowed every method several times over on 2 cores.
``docs/libraries.md`` reads the figures.

Modules: ``peers`` (which libraries, their threads), ``timing`` (interleaved rounds), ``inputs`` (steps, polish
stages, offsets), ``local_maps`` (each method's voxel grid, map, nearest points and polish), ``sequence`` (every
piece on one sequence), ``startup`` (import and first calls in fresh processes), ``table`` (markdown).
"""
