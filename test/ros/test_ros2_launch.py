"""``ros2 launch cemnet_ros align_node.launch.py`` for real, from a colcon-like install (test/ros/install_layout.py);
skips without the launch system and ros2 CLI (./run installs them from ../shared/ros2)."""
from __future__ import annotations

import subprocess

import pytest
from install_layout import make_install_prefix, ros2_cli_missing, ros_environment

pytestmark = [pytest.mark.dds, pytest.mark.skipif(bool(ros2_cli_missing()), reason=ros2_cli_missing() or "-")]
LAUNCH = ["ros2", "launch", "cemnet_ros", "align_node.launch.py"]


@pytest.fixture(scope="module")
def install_prefix(tmp_path_factory):
    return make_install_prefix(tmp_path_factory.mktemp("colcon") / "install")


def test_rviz_true_without_rviz2_fails_clearly_before_starting_the_node(install_prefix):
    run = subprocess.run([*LAUNCH, "rviz:=true"], env=ros_environment(install_prefix, 211), capture_output=True,
                         text=True, timeout=60)
    output = run.stdout + run.stderr
    assert run.returncode != 0, output
    assert "rviz:=true but the rviz2 package is not installed" in output, output
    assert "process started" not in output, "a process was started although the launch failed"


def test_a_missing_dds_profile_fails_clearly_before_starting_the_node(install_prefix, tmp_path):
    run = subprocess.run([*LAUNCH, f"dds_profile:={tmp_path / 'missing.xml'}"],
                         env=ros_environment(install_prefix, 212), capture_output=True, text=True, timeout=60)
    output = run.stdout + run.stderr
    assert run.returncode != 0 and "no such file" in output and "process started" not in output, output
