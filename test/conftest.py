"""Shared test fixtures."""
from pathlib import Path

import numpy as np
import pytest

KERNEL_FOLDERS = {"core", "pipeline", "ros", "replay", "tools", "bench", "train", "eval"}  # tests that run numba


@pytest.fixture(scope="session", autouse=True)
def compiled_kernels(request):
    """The numba kernels made ready once per session (compiled and cached, ~1 min on 2 cores, when no cache has
    them yet; loaded in seconds after that), before the first test instead of inside whichever test runs them
    first: each test's time and timeouts stay its own. Skipped when no selected test needs them."""
    if any(Path(item.path).parent.name in KERNEL_FOLDERS for item in request.session.items):
        from cemnet_ros.core import lattice_rewards
        from cemnet_ros.pipeline.steps import preprocess, refine
        from cemnet_ros.runtime.kernel_warmup import cache_complete
        from cemnet_ros.tools.warm_kernels import warm_up

        if not cache_complete():  # else the first node made in a test would warm up (cemnet_ros/ros/kernels.py)
            warm_up()

        lattice_rewards.compile_kernels()
        preprocess.compile_kernels()
        refine.compile_kernels()


@pytest.fixture
def bracket():
    """The package's procedural asymmetric shape, 1024 points in the unit sphere."""
    from cemnet_ros.data.shapes import bracket_shape
    return bracket_shape(1024, seed=0).astype(np.float64)


@pytest.fixture(scope="session")
def tiny_bag(tmp_path_factory) -> Path:
    """4 ray-cast scans (16 beams x 360 steps) of the synthetic courtyard with ground truth."""
    from cemnet_ros.data import scenes
    from cemnet_ros.data.bags import write_bag

    scene, lidar = scenes.courtyard_scene(), scenes.LidarModel(n_beams=16, n_azimuth=360)
    rng = np.random.default_rng(3)
    frames = [(scenes.lidar_scan(scene, pose, lidar, rng), pose) for pose in scenes.synthetic_trajectory(4)]
    path = tmp_path_factory.mktemp("bags") / "tiny.mcap"
    write_bag(path, frames, "lidar", 100_000_000)
    return path
