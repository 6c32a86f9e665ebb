#!/usr/bin/env bash
# Install the ROS 2 launch system and `ros2` command line built in ../shared/ros2 (no pip wheels exist for them)
# into the venv, with their PyPI dependencies and composition_interfaces (launch_ros imports it). Harmless
# without ../shared/ros2: says so and exits 0, and the tests that need `ros2 launch` skip.
#
# usage: scripts/install_shared_ros2.sh     (VENV: the venv, default .venv; SHARED_ROS2: default ../shared/ros2)
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
VENV=$(cd "${VENV:-$ROOT/.venv}" && pwd)
SHARED=${SHARED_ROS2:-$ROOT/../shared/ros2}
if [ ! -d "$SHARED/wheels" ]; then
  echo "install_shared_ros2: no $SHARED/wheels: launch and the ros2 CLI are not installed"
  exit 0
fi
# Not launch_testing*: their pytest plugin fails to load under the pytest installed here, and nothing needs them.
WHEELS=$(ls "$SHARED"/wheels/*.whl | grep -v '/launch_testing')
# Their PyPI dependencies first, then the wheels themselves without a resolver run: launch_ros's metadata names
# `ament-index-python`, a distribution no index has (the module is ros-jazzy-ament-index-python's, which the rclpy
# wheels bring), so pip's resolver would report it missing although `import ament_index_python` works.
"$VENV/bin/python" -m pip install -q --disable-pip-version-check osrf-pycommon psutil ros-jazzy-ament-index-python
# shellcheck disable=SC2086
"$VENV/bin/python" -m pip install -q --disable-pip-version-check --no-deps $WHEELS
VENV="$VENV" bash "$ROOT/scripts/build_interface_package.sh" "$SHARED/src/composition_interfaces"
"$VENV/bin/python" -c "import launch_ros.actions, ros2cli" && echo "install_shared_ros2: ok, launch_ros and ros2cli importable"
