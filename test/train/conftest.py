"""Fixtures of the training tests."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from tiny_training import TINY, box_union_shapes

from cemnet_ros.data.scenes import LidarModel, courtyard_scene, lidar_scan, synthetic_trajectory
from cemnet_ros.replay.bag_io import BagWriter

N_SCANS = 8
START_NS = 1_700_000_000_000_000_000


@pytest.fixture(scope="module")
def shapes_npz(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("shapes") / "tiny.npz"
    n = 12
    np.savez(path, points=box_union_shapes(n, TINY.n_points, seed=1), labels=np.arange(n) % 4,
             split=np.array(["train"] * 10 + ["test"] * 2))
    return path


@pytest.fixture(scope="module")
def scans_and_poses():
    """8 ray-cast courtyard scans (16 x 360 rays) along the synthetic trajectory, and their poses."""
    lidar, rng = LidarModel(n_beams=16, n_azimuth=360), np.random.default_rng(0)
    poses = synthetic_trajectory(N_SCANS, step=1.0)
    return [lidar_scan(courtyard_scene(), pose, lidar, rng) for pose in poses], poses


@pytest.fixture(scope="module")
def training_bag(scans_and_poses, tmp_path_factory) -> Path:
    """Those scans on /points with /ground_truth, as an .mcap bag."""
    path = tmp_path_factory.mktemp("bag") / "courtyard.mcap"
    with BagWriter(path) as bag:
        for i, (points, pose) in enumerate(zip(*scans_and_poses)):
            bag.write_cloud("/points", points, "lidar", START_NS + i * 100_000_000)
            bag.write_pose("/ground_truth", pose, "world", START_NS + i * 100_000_000)
    return path
