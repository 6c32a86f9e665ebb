"""The local map that tracking registers against: a voxel hash map of points with normals, in the odom frame.

``voxel_map`` (:class:`~cemnet_ros.pipeline.map.voxel_map.VoxelMap`, the map itself), and its numba kernels:
``voxel_hash`` (storage: the hash table, insertion, pruning), ``voxel_normals`` (each new point's normal and
planarity) and ``voxel_query`` (nearest map point, points within a ball). Import from the modules; this package
stays import-light (no torch).
"""
