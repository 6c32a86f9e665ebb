"""The repository is a proper ament_python package: colcon builds it and installs the ros2-run executables, which run
the python3 on PATH; a python3 that cannot import the node's dependencies fails the build with the fix."""
import os
import subprocess
import sys
import venv
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
COLCON = Path(sys.executable).with_name("colcon")
VENV_BIN = Path(sys.executable).parent
SHEBANG = "#!/usr/bin/env python3"

pytestmark = pytest.mark.skipif(not COLCON.exists(), reason="colcon is not installed (pip install -e '.[test]' "
                                                            "brings it)")


def colcon_build(workspace: Path, path: str, *options: str) -> subprocess.CompletedProcess:
    """``colcon build`` of this package into ``workspace`` with ``path`` as PATH (which decides the python3 the
    executables will run); colcon itself runs on this venv's interpreter, as a pip-installed colcon does."""
    env = {**os.environ, "COLCON_HOME": str(workspace), "PATH": path}
    env.pop("CEMNET_SKIP_RUNTIME_CHECK", None)
    return subprocess.run(
        [str(COLCON), "--log-base", str(workspace / "log"), "build", "--base-paths", str(REPO),
         "--build-base", str(workspace / "build"), "--install-base", str(workspace / "install"),
         "--packages-select", "cemnet_ros", *options],
        cwd=workspace, capture_output=True, text=True, timeout=600, env=env)


def with_venv_first() -> str:
    """PATH of a shell with this venv activated: its python3 has torch, numba, small_gicp and rclpy."""
    return os.pathsep.join([str(VENV_BIN), os.environ.get("PATH", "")])


def test_colcon_build_installs_the_node_and_tools(tmp_path):
    result = colcon_build(tmp_path, with_venv_first())
    assert result.returncode == 0, result.stdout + result.stderr
    install = tmp_path / "install" / "cemnet_ros"
    for script in ("align_node", "align_lifecycle_node", "cemnet-replay", "cemnet-eval", "cemnet-train"):
        path = install / "lib" / "cemnet_ros" / script  # where `ros2 run` looks
        assert path.read_text().splitlines()[0] == SHEBANG, script  # not the interpreter colcon ran on
    assert (install / "share" / "ament_index" / "resource_index" / "packages" / "cemnet_ros").is_file()
    assert (install / "share" / "cemnet_ros" / "package.xml").is_file()
    assert (install / "share" / "cemnet_ros" / "config" / "align_node.yaml").is_file()
    assert list(install.rglob("weights/official_modelnet40_clean.npz"))
    assert list(install.rglob("weights/cemnet_ros_modelnet40_clean.npz"))
    assert "tests_require" not in result.stdout + result.stderr


def test_a_symlink_install_writes_the_same_executables(tmp_path):
    result = colcon_build(tmp_path, with_venv_first(), "--symlink-install")
    assert result.returncode == 0, result.stdout + result.stderr
    script = tmp_path / "install" / "cemnet_ros" / "lib" / "cemnet_ros" / "align_node"
    assert script.read_text().splitlines()[0] == SHEBANG


def test_a_python3_without_torch_fails_the_build_with_the_fix(tmp_path):
    """The python3 on PATH is a bare venv (the interpreter a ROS user's colcon would find without the venv that
    has torch): the build fails before installing and says what is missing and how to fix it."""
    bare = tmp_path / "bare"
    venv.create(bare, with_pip=False)
    result = colcon_build(tmp_path, os.pathsep.join([str(bare / "bin"), with_venv_first()]))
    output = result.stdout + result.stderr
    assert result.returncode != 0, output
    assert f"here {bare / 'bin' / 'python3'}" in output and "which cannot import" in output, output
    missing = output.split("which cannot import:")[1].splitlines()[0]
    assert {"torch", "numba", "small_gicp", "rclpy"} <= set(missing.strip(" .").split(", ")), missing
    assert "pip install -r src/cemnet_ros/requirements-ros.txt" in output and "CEMNET_SKIP_RUNTIME_CHECK" in output
    assert not (tmp_path / "install" / "cemnet_ros" / "lib" / "cemnet_ros" / "align_node").exists()
