"""The repository is a proper ament_python package: colcon builds it and installs the ros2-run executables."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
COLCON = Path(sys.executable).with_name("colcon")


@pytest.mark.skipif(not COLCON.exists(), reason="colcon is not installed (pip install -e '.[test]' brings it)")
def test_colcon_build_installs_the_node_and_tools(tmp_path):
    result = subprocess.run(
        [str(COLCON), "--log-base", str(tmp_path / "log"), "build", "--base-paths", str(REPO),
         "--build-base", str(tmp_path / "build"), "--install-base", str(tmp_path / "install"),
         "--packages-select", "cemnet_ros"],
        cwd=tmp_path, capture_output=True, text=True, timeout=600, env={**os.environ, "COLCON_HOME": str(tmp_path)})
    assert result.returncode == 0, result.stdout + result.stderr
    install = tmp_path / "install" / "cemnet_ros"
    for script in ("align_node", "cemnet-replay", "cemnet-eval", "cemnet-train"):
        assert (install / "lib" / "cemnet_ros" / script).is_file(), script  # where `ros2 run` looks
    assert (install / "share" / "ament_index" / "resource_index" / "packages" / "cemnet_ros").is_file()
    assert (install / "share" / "cemnet_ros" / "package.xml").is_file()
    assert (install / "share" / "cemnet_ros" / "config" / "align_node.yaml").is_file()
    assert list(install.rglob("weights/official_modelnet40_clean.npz"))
    assert list(install.rglob("weights/cemnet_ros_modelnet40_clean.npz"))
