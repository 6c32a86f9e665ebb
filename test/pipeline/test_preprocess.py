"""Scan preprocessing: finite points, range crop, voxel centroids, subsets, robust radius."""
import numpy as np
import pytest

from cemnet_ros.pipeline.steps.preprocess import (
    farthest_point_indices,
    finite_in_range,
    finite_points,
    robust_radius,
    subsample,
    voxel_downsample,
    voxel_downsample_in_range,
)


def test_finite_and_crop():
    pts = np.array([[1, 0, 0], [np.nan, 0, 0], [5, 0, 0], [0, 20, 0], [0, 0, np.inf]], dtype=float)
    fin = finite_points(pts)
    assert len(fin) == 3
    np.testing.assert_array_equal(finite_in_range(pts, 2.0, 10.0), [[5, 0, 0]])
    np.testing.assert_array_equal(finite_in_range(pts, 0.0, 0.0), fin)
    np.testing.assert_array_equal(finite_in_range(pts, 2.0, 0.0), [[5, 0, 0], [0, 20, 0]])  # no inf beyond "no max"
    np.testing.assert_array_equal(finite_in_range(pts.astype(np.float32), 0.0, 10.0), [[1, 0, 0], [5, 0, 0]])
    with pytest.raises(ValueError):
        finite_points(np.zeros((3, 2)))
    with pytest.raises(ValueError):
        finite_in_range(np.zeros((3, 2)), 1.0, 2.0)


def test_voxel_downsample_takes_centroids():
    pts = np.array([[0.1, 0.1, 0.1], [0.3, 0.3, 0.3], [1.5, 0.2, 0.2], [-0.5, 0.5, 0.5]])
    out = voxel_downsample(pts, 1.0)
    expected = np.array([[-0.5, 0.5, 0.5], [0.2, 0.2, 0.2], [1.5, 0.2, 0.2]])
    np.testing.assert_allclose(out[np.lexsort(out.T[::-1])], expected[np.lexsort(expected.T[::-1])])
    np.testing.assert_array_equal(voxel_downsample(pts, 0.0), pts)


def test_voxel_downsample_in_range_is_the_crop_then_the_grid_bit_for_bit():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-30.0, 30.0, (20000, 3))
    pts[::7] = np.nan
    pts[3::11, 1] = np.inf
    for min_range, max_range in [(0.0, 0.0), (2.0, 25.0), (0.0, 10.0)]:
        kept = finite_in_range(pts, min_range, max_range)
        for source in (pts, pts.astype(np.float32)):
            dense, n_in_range = voxel_downsample_in_range(source, 0.7, min_range, max_range)
            expected = voxel_downsample(finite_in_range(source, min_range, max_range), 0.7)
            assert n_in_range == len(kept)
            np.testing.assert_array_equal(dense, expected)
    with_intensity = np.hstack([pts, np.ones((len(pts), 1))]).astype(np.float32)
    np.testing.assert_array_equal(voxel_downsample_in_range(with_intensity[:, :3], 0.7)[0],
                                  voxel_downsample(finite_points(with_intensity[:, :3]), 0.7))
    np.testing.assert_array_equal(voxel_downsample_in_range(pts, 0.0, 2.0, 25.0)[0], finite_in_range(pts, 2.0, 25.0))
    empty, none_in_range = voxel_downsample_in_range(pts, 0.7, 100.0, 200.0)
    assert empty.shape == (0, 3) and none_in_range == 0


def test_subsample_is_seeded_and_farthest_spreads():
    pts = np.random.default_rng(0).normal(size=(500, 3))
    a, b = subsample(pts, 50, "random", seed=3), subsample(pts, 50, "random", seed=3)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, subsample(pts, 50, "random", seed=4))
    assert len(subsample(pts[:10], 50)) == 10
    # Farthest-point sampling of two tight clusters picks from both at once.
    clusters = np.vstack([np.zeros((100, 3)), np.full((100, 3), 10.0)]) + np.random.default_rng(1).normal(
        scale=0.01, size=(200, 3))
    idx = farthest_point_indices(clusters, 2)
    assert (idx < 100).sum() == 1
    with pytest.raises(ValueError):
        subsample(pts, 10, "bogus")


def test_robust_radius_ignores_outliers():
    pts = np.random.default_rng(0).uniform(-1, 1, (5000, 3)) + 50.0
    clean = robust_radius(pts)
    assert 0.9 < clean < 1.5
    assert robust_radius(np.vstack([pts, np.full((20, 3), 1e6)])) == pytest.approx(clean, rel=0.05)
    with pytest.raises(ValueError):
        robust_radius(np.zeros((0, 3)))
