"""What a scan saw as empty: the space between its sensor and the points it hit.

A pose that puts another scan's points in that space contradicts the scan: its sensor looked through where they
would be. The fitness (the share of points on the map's surfaces) cannot tell a wrong answer from a right one
where the right one overlaps the map little (sparse keyframes, far pairs) and the wrong one fits the ground and
a few walls (a car that "did not move" on a road whose ground rings fit at any stop): the free space can, because
the wrong answer puts what the scan saw ahead inside what the map's scan saw through.

A point is in the free space when every ray of the scan within the scan's own angular spacing (twice the median
angle between neighbouring rays: a sparse keyframe's rays are wider than a dense sweep's) hit farther than the
point by ``margin`` m plus ``relative_margin`` of that range (range noise, beam width, the reference's error). A
direction no ray saw is unknown, not free.
"""
from __future__ import annotations

from typing import Optional

import numpy as np
from scipy.spatial import cKDTree

MIN_RANGE_M = 0.5  # points this close to a sensor carry no direction worth the name
RAYS = 8  # rays compared within the angular spacing
MAX_RAYS = 6000  # rays kept (a dense scan's are subsampled: the build is most of the cost, the spacing adapts)
SPACING_SAMPLES = 500  # rays whose nearest neighbour measures the spacing (a median: a sample tells it)
MARGIN_M, RELATIVE_MARGIN = 1.0, 0.05  # in front of a hit by more than this is through it


class FreeSpace:
    """The rays of one scan: its ``points`` (n, 3, odom frame, as the map took them in: the voxel grid, not a
    thinner cloud, whose centroids would stand in front of the rays they replace) from ``sensor`` (3,) in odom."""

    def __init__(self, points: np.ndarray, sensor: Optional[np.ndarray] = None) -> None:
        self.sensor = np.zeros(3) if sensor is None else np.asarray(sensor, dtype=np.float64).reshape(3)
        rays = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if len(rays) > MAX_RAYS:  # a seeded subset: real hits, a wider spacing, no stride aliasing an organised scan
            rays = rays[np.sort(np.random.default_rng(0).choice(len(rays), MAX_RAYS, replace=False))]
        rays = rays - self.sensor
        ranges = np.linalg.norm(rays, axis=1)
        kept = ranges > MIN_RANGE_M
        self.ranges = ranges[kept]
        # built once a scan and queried once or twice: an unbalanced tree builds in half the time
        directions = rays[kept] / self.ranges[:, None]
        self._tree = cKDTree(directions, balanced_tree=False) if len(self.ranges) >= 2 else None
        if self._tree is None:
            self.spacing = 0.0
            return
        sampled = directions[::max(1, len(directions) // SPACING_SAMPLES)]
        neighbour, _ = self._tree.query(sampled, k=2)
        self.spacing = 2.0 * float(np.median(neighbour[:, 1]))

    def seen_through(self, points_odom: np.ndarray) -> float:
        """The share of ``points_odom`` (n, 3) that lie in this scan's free space (0 for none)."""
        points_odom = np.asarray(points_odom, dtype=np.float64).reshape(-1, 3)
        if self._tree is None or not len(points_odom):
            return 0.0
        local = points_odom - self.sensor
        ranges = np.linalg.norm(local, axis=1)
        kept = ranges > MIN_RANGE_M
        chord, index = self._tree.query(local[kept] / ranges[kept, None], k=RAYS, distance_upper_bound=self.spacing)
        hit = np.where(np.isfinite(chord), self.ranges[np.minimum(index, len(self.ranges) - 1)], np.inf)
        nearest_hit = hit.min(axis=1)
        through = np.isfinite(nearest_hit) & (ranges[kept] < nearest_hit * (1.0 - RELATIVE_MARGIN) - MARGIN_M)
        return float(np.count_nonzero(through)) / len(points_odom)
