"""What a scan saw empty (cemnet_ros.pipeline.map.free_space): points in front of its hits are seen through."""
from __future__ import annotations

import numpy as np

from cemnet_ros.pipeline.map.free_space import MAX_RAYS, FreeSpace


def wall_ring(radius: float, n: int, z_levels: int = 8) -> np.ndarray:
    """A cylinder of hits around the sensor at the origin: ``n`` rays over azimuth and +-0.2 rad of elevation."""
    azimuth = np.repeat(np.linspace(-np.pi, np.pi, n // z_levels, endpoint=False), z_levels)
    elevation = np.tile(np.linspace(-0.2, 0.2, z_levels), n // z_levels)
    return radius * np.column_stack([np.cos(azimuth) * np.cos(elevation), np.sin(azimuth) * np.cos(elevation),
                                     np.sin(elevation)])


def test_points_in_front_of_the_hits_are_seen_through_and_points_on_or_behind_them_are_not():
    scan = FreeSpace(wall_ring(10.0, 4000), sensor=np.zeros(3))
    directions = wall_ring(1.0, 400)
    assert scan.seen_through(5.0 * directions) == 1.0  # halfway to the wall: the rays passed there
    assert scan.seen_through(10.0 * directions) == 0.0  # on the wall
    assert scan.seen_through(9.2 * directions) == 0.0  # within the margin (1 m + 5 %) of the hit
    assert scan.seen_through(15.0 * directions) == 0.0  # behind the wall: occluded, not seen
    mixed = np.vstack([5.0 * directions[:100], 10.0 * directions[100:]])
    assert scan.seen_through(mixed) == 0.25


def test_a_direction_no_ray_saw_is_unknown_not_free():
    scan = FreeSpace(wall_ring(10.0, 4000), sensor=np.zeros(3))
    assert scan.seen_through(np.array([[0.0, 0.0, 5.0], [0.0, 0.0, -5.0]])) == 0.0  # straight up and down


def test_the_sensor_position_is_where_the_rays_start():
    sensor = np.array([3.0, -2.0, 1.0])
    scan = FreeSpace(wall_ring(10.0, 4000) + sensor, sensor=sensor)
    assert scan.seen_through(sensor + 5.0 * wall_ring(1.0, 400)) == 1.0
    assert scan.seen_through(5.0 * wall_ring(1.0, 400)) < 1.0  # the same points from the origin: not all in front


def test_a_dense_organised_scan_keeps_a_subset_of_its_rays_and_says_the_same():
    dense = FreeSpace(wall_ring(10.0, 4 * MAX_RAYS), sensor=np.zeros(3))
    assert len(dense.ranges) <= MAX_RAYS
    # a subset leaves gaps wider than twice its median spacing here and there: unknown there, never free; every
    # ring keeps rays (every k-th ray of this ring-major layout would keep 2 of its 8 rings: a quarter seen)
    assert dense.seen_through(5.0 * wall_ring(1.0, 400)) > 0.85
    assert dense.seen_through(10.0 * wall_ring(1.0, 400)) == 0.0


def test_an_empty_scan_or_query_sees_nothing():
    assert FreeSpace(np.empty((0, 3))).seen_through(np.ones((5, 3))) == 0.0
    assert FreeSpace(wall_ring(10.0, 4000)).seen_through(np.empty((0, 3))) == 0.0
