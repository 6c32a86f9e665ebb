"""cemnet-warm-kernels compiles what the node's first scans need and marks the cache complete: afterwards the node's
path compiles nothing, and a node starting there does not warm up again."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
NODE_PATH = """
import sys
from cemnet_ros.pipeline.config import AlignerConfig
from cemnet_ros.runtime.aligner_session import AlignerSession
from cemnet_ros.runtime.extrinsic import BaseFrame
from cemnet_ros.runtime.odometry_output import aligned_points
from cemnet_ros.replay.bag_io import BagReader
from cemnet_ros.ros.node_config import NodeConfig
from cemnet_ros.runtime.kernel_warmup import cache_counts
import numpy as np

session = AlignerSession(AlignerConfig(), NodeConfig(), BaseFrame(np.eye(4)))
session.load()
with BagReader(sys.argv[1]) as reader:
    for frame in reader.clouds(3):
        result = session.process(frame, frame.frame_id, None)
        aligned_points(frame.points, result.T_odom_sensor, 0.2)
print(*cache_counts())
"""


@pytest.mark.slow
def test_after_warming_the_nodes_first_scans_load_every_kernel_from_the_cache(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}  # an empty cache, as after an install
    warm = subprocess.run([sys.executable, "-m", "cemnet_ros.tools.warm_kernels"], env=env, capture_output=True,
                          text=True, timeout=900)
    assert warm.returncode == 0, warm.stderr[-2000:]
    assert " 0 loaded from the cache" in warm.stdout and str(tmp_path / "cache") in warm.stdout
    complete = subprocess.run([sys.executable, "-c", "from cemnet_ros.runtime.kernel_warmup import cache_complete; "
                               "print(cache_complete())"], env=env, capture_output=True, text=True, timeout=300)
    assert complete.stdout.split() == ["True"], complete.stderr[-2000:]
    node = subprocess.run([sys.executable, "-c", NODE_PATH, str(REPO / "bags" / "kitti_00_6scans.mcap")], env=env,
                          capture_output=True, text=True, timeout=900)
    assert node.returncode == 0, node.stderr[-2000:]
    loaded, compiled = (int(v) for v in node.stdout.split()[-2:])
    assert compiled == 0 and loaded > 0
    check = subprocess.run([sys.executable, "-m", "cemnet_ros.tools.warm_kernels", "--check"], env=env,
                           capture_output=True, text=True, timeout=900)
    assert check.returncode == 0, check.stderr[-2000:]
