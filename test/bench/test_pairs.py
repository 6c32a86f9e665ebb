"""Pair sets from a bag: real scans of a bag with ground truth, at the recovery's motions, with their truth."""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from benchmarks.pairs import bag_pairs, read_posed_scans
from cemnet_ros.core.geometry import apply_transform, matrix_to_action_np


def test_bag_pairs_carry_the_truth_of_a_large_motion(tiny_bag):
    pairs = bag_pairs(*read_posed_scans(tiny_bag), 12, seed=0, max_translation=10.0)
    yaws = []
    for pair in pairs:
        moved = apply_transform(pair.truth, pair.second)  # in the first scan's frame (16 x 360 rays: sparse)
        before = np.median(cKDTree(pair.first).query(pair.second)[0])
        after = np.median(cKDTree(pair.first).query(moved)[0])
        assert after < 0.5 and (before > 3.0 * after or abs(matrix_to_action_np(pair.truth)[0]) < 0.2)
        assert np.linalg.norm(pair.truth[:2, 3]) <= 10.0 + 1e-9  # sensors at most max_translation apart
        yaws.append(np.degrees(matrix_to_action_np(pair.truth)[0]))
    assert max(yaws) - min(yaws) > 180.0  # yaw over the circle, not only the trajectory's turns
