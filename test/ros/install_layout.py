"""A colcon-like install prefix of this package, made from setup.py, for `ros2 launch` / `ros2 run` tests.

`pip install -e .` installs no share/ files and puts console scripts in the venv's bin/; `ros2 launch` and
`ros2 run` find a package through AMENT_PREFIX_PATH in colcon's layout: ``lib/cemnet_ros/<executable>``,
``share/cemnet_ros/...`` and ``share/ament_index/resource_index/packages/cemnet_ros``. The data files are links
to the source tree, the executables to the venv's console scripts (this checkout's code).
"""
from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

from package_files import PACKAGE, REPO, setup_keyword

VENV_BIN = Path(sys.executable).parent
SHARED_ROS2 = REPO.parent / "shared" / "ros2"


def ros2_cli_missing() -> str:
    """Why `ros2 launch` cannot run here ('' when it can): ../shared/ros2 is installed by ./run."""
    if shutil.which("ros2", path=str(VENV_BIN)) is None:
        return f"no ros2 CLI in {VENV_BIN} (./run installs it from {SHARED_ROS2} when that exists)"
    try:
        import launch_ros.actions  # noqa: F401
    except ImportError as exc:
        return f"launch_ros not importable: {exc}"
    return ""


def make_install_prefix(prefix: Path) -> Path:
    """Lay this package out under ``prefix`` as colcon would install it; ``prefix``."""
    for destination, paths in setup_keyword("data_files"):
        folder = prefix / destination
        folder.mkdir(parents=True, exist_ok=True)
        for path in paths:
            (folder / Path(path).name).symlink_to(REPO / path)
    executables = prefix / "lib" / PACKAGE
    executables.mkdir(parents=True)
    for script in setup_keyword("entry_points")["console_scripts"]:
        name = script.split("=")[0].strip()
        (executables / name).symlink_to(VENV_BIN / name)
    return prefix


def add_stand_in_executable(prefix: Path, package: str, executable: str, script: str) -> None:
    """An ament package ``package`` in ``prefix`` whose ``lib/<package>/<executable>`` is the shell ``script``
    (e.g. an rviz2 that only says it was started, where RViz2 is not installed)."""
    marker = prefix / "share" / "ament_index" / "resource_index" / "packages" / package
    marker.parent.mkdir(parents=True, exist_ok=True)
    marker.touch()
    path = prefix / "lib" / package / executable
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("#!/bin/sh\n" + script + "\n")
    path.chmod(0o755)


def ros_environment(prefix: Path, domain_id: int) -> dict:
    """The environment of a shell that sourced the install: AMENT_PREFIX_PATH, the venv's bin first on PATH,
    a private DDS domain on this host."""
    env = dict(os.environ)
    env["AMENT_PREFIX_PATH"] = os.pathsep.join([str(prefix), str(VENV_BIN.parent)])
    env["PATH"] = os.pathsep.join([str(VENV_BIN), env.get("PATH", "")])
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["PYTHONUNBUFFERED"] = "1"
    return env
