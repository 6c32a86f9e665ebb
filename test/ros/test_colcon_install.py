"""A ROS user's first start: ``colcon build`` into a new workspace, ``source install/setup.bash``, start
``install/cemnet_ros/lib/cemnet_ros/align_node``. The install is fresh, so its numba kernel cache is empty: the node
compiles the kernels before it subscribes and logs it, then aligns scans; the next start loads them from the cache
kept in the install. Ctrl-C stops it with status 0."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from node_harness import POSES, pose_of, scan_msg
from ros_cli import domain_id, interrupt, kill_group, start
from scan_driver import Driver

from benchmarks.metrics import relative_error

REPO = Path(__file__).resolve().parents[2]
COLCON = Path(sys.executable).with_name("colcon")
VENV_BIN = Path(sys.executable).parent
COMPILE_TIMEOUT = 900.0  # a cold kernel compile on 2 busy cores: minutes

pytestmark = [pytest.mark.dds, pytest.mark.slow,
              pytest.mark.skipif(not COLCON.exists(), reason="colcon is not installed (pip install -e '.[test]')")]


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    """A colcon workspace with this package built (a plain `colcon build`, the venv's python3 first on PATH)."""
    root = tmp_path_factory.mktemp("cemnet_ws")
    env = {**os.environ, "COLCON_HOME": str(root), "PATH": os.pathsep.join([str(VENV_BIN), os.environ["PATH"]])}
    built = subprocess.run([str(COLCON), "build", "--base-paths", str(REPO), "--packages-select", "cemnet_ros"],
                           cwd=root, env=env, capture_output=True, text=True, timeout=600)
    assert built.returncode == 0, built.stdout + built.stderr
    return root


def _start_installed_node(workspace: Path, domain: int):
    """`source install/setup.bash` and the installed executable, in a shell with the venv activated."""
    env = {key: value for key, value in os.environ.items()
           if key not in ("NUMBA_CACHE_DIR", "AMENT_PREFIX_PATH", "PYTHONPATH")}
    env.update(PATH=os.pathsep.join([str(VENV_BIN), env["PATH"]]), ROS_DOMAIN_ID=str(domain),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")
    script = (f"source {workspace}/install/setup.bash && "
              f"exec {workspace}/install/cemnet_ros/lib/cemnet_ros/align_node --ros-args -p qos_reliability:=reliable")
    return start(["bash", "-c", script], env)


def test_the_installed_node_compiles_its_kernels_before_subscribing_then_aligns_and_stops_on_ctrl_c(workspace):
    site = next((workspace / "install" / "cemnet_ros" / "lib").glob("python3*/site-packages"))
    cache = site / "cemnet_ros" / "__pycache__"
    assert not list(cache.glob("numba-*")), "a fresh install has no kernel cache"
    domain = domain_id()
    node, output = _start_installed_node(workspace, domain)
    driver = None
    try:
        assert output.wait_for("align_node subscribed", COMPILE_TIMEOUT), output.text()
        driver = Driver(domain)
        estimates = [pose_of(driver.send(scan_msg(k))) for k in range(3)]
        interrupt(node)
    finally:
        if driver is not None:
            driver.close()
        kill_group(node)
    log = output.text(timeout=10.0)
    assert node.returncode == 0 and "Traceback" not in log, log
    lines = log.splitlines()
    compiling = next(i for i, line in enumerate(lines) if "compiling them now, before subscribing" in line)
    compiled = next(i for i, line in enumerate(lines) if "versions compiled" in line)
    subscribed = next(i for i, line in enumerate(lines) if "align_node subscribed" in line)
    assert compiling < compiled < subscribed, log
    assert f"no complete cache in {cache}/numba-" in lines[compiling], lines[compiling]  # the install's own package
    assert "0 compiled" in next(line for line in lines if "engine ready" in line), log  # warmed before the load
    for k, estimate in enumerate(estimates):
        trans_err, rot_err = relative_error(estimate, np.linalg.inv(POSES[0]) @ POSES[k])
        assert trans_err < 0.03 * k + 0.01 and rot_err < 0.1 * k + 0.01, (k, trans_err, rot_err)

    again, output = _start_installed_node(workspace, domain_id())  # the next start: kernels from the install's cache
    try:
        assert output.wait_for("engine ready", 300.0), output.text()
        interrupt(again)
    finally:
        kill_group(again)
    log = output.text(timeout=10.0)
    assert f"numba kernels: the cache {cache}/numba-" in log and "is complete" in log, log
    assert "compiling them now" not in log and "0 compiled" in log and again.returncode == 0, log
