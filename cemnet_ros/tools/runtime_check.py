"""Can the ``python3`` that will run the installed node import what the node needs? ``colcon build`` asks at build time.

The installed executables (``lib/cemnet_ros/align_node``, ...) start with ``#!/usr/bin/env python3`` (setup.cfg): they
run the first ``python3`` on PATH (an activated venv's), not the interpreter colcon itself runs on, which may be the
system's without torch. ``setup.py install``/``develop`` (what colcon runs) calls :func:`problem` before installing
and fails the build with its message, so that a missing torch shows at build time with its fix, not as an
ImportError at the first launch. ``CEMNET_SKIP_RUNTIME_CHECK=1`` skips it (an image that installs torch later).

    python3 -m cemnet_ros.tools.runtime_check      # the same check by hand: exit 1 and the fix, or one line

Standard library only: setup.py loads this file by path, before anything is installed.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from typing import Mapping, Optional

SKIP_VARIABLE = "CEMNET_SKIP_RUNTIME_CHECK"
ROS, ROSDEP, PIP = "ros", "rosdep", "pip"
# The node's imports outside the standard library and ROS's messages, each with where it comes from.
REQUIRED = {"rclpy": ROS, "numpy": ROSDEP, "scipy": ROSDEP, "numba": ROSDEP, "yaml": ROSDEP, "tqdm": ROSDEP,
            "torch": PIP, "small_gicp": PIP}
FIXES = {
    ROS: "source /opt/ros/jazzy/setup.bash (rclpy comes with ROS 2)",
    ROSDEP: "rosdep install --from-paths src --ignore-src -y (numpy, scipy, numba, PyYAML, tqdm)",
    PIP: "python3 -m pip install -r src/cemnet_ros/requirements-ros.txt in the venv the node runs in (torch, "
         "small-gicp; on a Jetson install NVIDIA's torch wheel first), then `source <venv>/bin/activate` before "
         "colcon build and in every shell that runs the node",
}
PROBE = ("import importlib.util, json, sys\n"
         "names = json.loads(sys.argv[1])\n"
         "print(json.dumps({'python': sys.executable, 'version': sys.version.split()[0],\n"
         "                  'missing': [n for n in names if importlib.util.find_spec(n) is None]}))\n")


def probe(python: str, env: Optional[Mapping[str, str]] = None) -> dict:
    """What ``python`` reports: its path, version and the :data:`REQUIRED` modules it cannot find."""
    done = subprocess.run([python, "-c", PROBE, json.dumps(sorted(REQUIRED))], capture_output=True, text=True,
                          env=None if env is None else dict(env), timeout=120)
    if done.returncode != 0:
        return {"python": python, "version": "?", "missing": sorted(REQUIRED),
                "error": (done.stderr.strip().splitlines() or ["no output"])[-1]}
    return json.loads(done.stdout.splitlines()[-1])


def problem(env: Optional[Mapping[str, str]] = None) -> Optional[str]:
    """Why the installed executables would not start (None: they would): the ``python3`` on ``env``'s PATH is
    missing, or cannot find a module of :data:`REQUIRED`. The message names the modules and the fix."""
    environ = os.environ if env is None else env
    python = shutil.which("python3", path=environ.get("PATH", os.defpath))
    if python is None:
        return "cemnet_ros: no python3 on PATH: the installed executables start `/usr/bin/env python3`"
    found = probe(python, environ)
    if not found["missing"]:
        return None
    kinds = sorted({REQUIRED[name] for name in found["missing"]}, key=[ROS, ROSDEP, PIP].index)
    lines = [f"cemnet_ros: the installed executables (lib/cemnet_ros/align_node, ...) start `/usr/bin/env python3`, "
             f"here {found['python']} (Python {found['version']}), which cannot import: "
             f"{', '.join(found['missing'])}" + (f" ({found['error']})" if "error" in found else "") + ".",
             "Fix, then build again:"]
    lines += [f"  - {FIXES[kind]}" for kind in kinds]
    lines.append(f"({SKIP_VARIABLE}=1 builds anyway, e.g. for an image that installs them later; docs/install_ros.md)")
    return "\n".join(lines)


def main() -> int:
    message = problem()
    if message is not None:
        print(message, file=sys.stderr)
        return 1
    python = shutil.which("python3")
    print(f"cemnet_ros: {python} imports {', '.join(sorted(REQUIRED))}: the installed executables will start")
    return 0


if __name__ == "__main__":
    sys.exit(main())
