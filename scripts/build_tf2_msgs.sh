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
#   WORK    scratch dir for build tools, sources and the cmake build (default: build/interfaces_ws)
# needs: gcc g++ make cmake>=3.21 (Debian: build-essential cmake), Python.h for
#        the venv's interpreter (Debian python: python3-dev), network to PyPI once.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
VENV=$(cd "${VENV:-$ROOT/.venv}" && pwd)
PREFIX=${1:-${PREFIX:-$VENV}}
WORK=${WORK:-$ROOT/build/interfaces_ws}
PY=$VENV/bin/python
PYVER=$($PY -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')
mkdir -p "$WORK" "$PREFIX"
PREFIX=$(cd "$PREFIX" && pwd)

# 1. package sources; the build: scripts/build_interface_package.sh
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
VENV="$VENV" WORK="$WORK" bash "$ROOT/scripts/build_interface_package.sh" "$SRC" "$PREFIX"

# 2. env for a prefix other than the venv, and a smoke test
cat > "$PREFIX/tf2_msgs_env.sh" <<EOF
export PYTHONPATH="$PREFIX/lib/python$PYVER/site-packages\${PYTHONPATH:+:\$PYTHONPATH}"
export LD_LIBRARY_PATH="$PREFIX/lib\${LD_LIBRARY_PATH:+:\$LD_LIBRARY_PATH}"
export AMENT_PREFIX_PATH="$PREFIX\${AMENT_PREFIX_PATH:+:\$AMENT_PREFIX_PATH}"
EOF
env -u PYTHONPATH bash -c ". '$PREFIX/tf2_msgs_env.sh' && '$PY' -c 'from tf2_msgs.msg import TFMessage; TFMessage.__class__.__import_type_support__(); assert TFMessage._TYPE_SUPPORT is not None; print(\"build_tf2_msgs: ok, tf2_msgs importable\")'"
if [ "$PREFIX" != "$VENV" ]; then
  echo "build_tf2_msgs: before running nodes:  . $PREFIX/tf2_msgs_env.sh"
fi
