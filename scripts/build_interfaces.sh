#!/usr/bin/env bash
# Build the typed ROS interfaces (crop_sim_interfaces/: msg, srv, action) into a Python virtual environment
# that holds the ROS 2 Jazzy wheels from PyPI (requirements.txt), with no ROS distribution installed:
#
#   scripts/build_interfaces.sh [VENV]        (VENV defaults to .venv; ./farm runs this at install)
#
# Afterwards `import crop_sim_interfaces.msg` works in VENV's python: the generated Python package lands in
# VENV/lib/python3.X/site-packages, its C libraries in VENV/lib (where the rclpy wheels' bootstrapper puts
# LD_LIBRARY_PATH), the ament index entry and the .msg/.srv/.action files in VENV/share. The build tree is
# build/crop_sim_interfaces (git-ignored; a rebuild reuses it).
#
# Needs: a C/C++ compiler, cmake >= 3.8, make, the Python headers of VENV's python (Debian: build-essential
# cmake python3.11-dev), and requirements.txt's rosidl/ament wheels in VENV. Missing pieces are named, exit 1.
#
# The wheels are not enough as published; the patches, all here (measured: shared/spec/ROS_INTERFACE.md):
#  1. rosidl_generator_py's exported CMake targets name the wheel builder's Python (/opt/python/cp311-...):
#     point them at VENV's Python and numpy include directories (idempotent: a patched file has no /opt/python);
#  2. the generators find each other and the message packages through AMENT_PREFIX_PATH / CMAKE_PREFIX_PATH:
#     both set to VENV (the wheels install their share/ and lib/ there);
#  3. the build-only wheels their metadata does not declare are pinned in requirements.txt.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=$(cd "${1:-.venv}" && pwd)
PY=$VENV/bin/python
SOURCE=$PWD/crop_sim_interfaces
BUILD=$PWD/build/crop_sim_interfaces

fail() { echo "build_interfaces: $*" >&2; exit 1; }

# --- what the build needs ----------------------------------------------------------------------------------
for tool in cc c++ cmake make; do
  command -v "$tool" > /dev/null || fail "$tool not found: install a C/C++ toolchain, cmake and make (Debian/Ubuntu: sudo apt-get install build-essential cmake)"
done
[ -x "$PY" ] || fail "no python in $VENV (make the virtual environment first: ./farm does)"
PYINC=$("$PY" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
PYVER=$("$PY" -c 'import sys; print(f"{sys.version_info.major}.{sys.version_info.minor}")')
[ -f "$PYINC/Python.h" ] || fail "Python.h missing in $PYINC: install the headers of Python $PYVER (Debian/Ubuntu: sudo apt-get install python$PYVER-dev)"
NPINC=$("$PY" -c 'import numpy; print(numpy.get_include())') || fail "numpy missing in $VENV (pip install -r requirements.txt)"
for package in ament_cmake rosidl_default_generators ament_cmake_ros python_cmake_module rosidl_core_generators; do
  [ -d "$VENV/share/$package/cmake" ] || fail "$package missing in $VENV/share: pip install -r requirements.txt (the ros-jazzy-* build wheels)"
done

# --- patch 1: the wheels' CMake files point at this machine's Python -------------------------------------
{ grep -rlE '/opt/python/' "$VENV/share" --include='*.cmake' || true; } | xargs -r sed -i -E \
  -e "s#/opt/python/[^;\"]*/site-packages/numpy/_core/include#$NPINC#g" \
  -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+/include/python3\.[0-9]+#$PYINC#g"

# --- patch 2 and the build ----------------------------------------------------------------------------------
export AMENT_PREFIX_PATH=$VENV CMAKE_PREFIX_PATH=$VENV PATH=$VENV/bin:$PATH
cmake -S "$SOURCE" -B "$BUILD" -DCMAKE_INSTALL_PREFIX="$VENV" -DCMAKE_BUILD_TYPE=Release \
  -DPython3_EXECUTABLE="$PY" -DPython3_FIND_VIRTUALENV=ONLY -DBUILD_TESTING=OFF
cmake --build "$BUILD" -j "$(nproc)"
cmake --install "$BUILD"

# --- it imports ---------------------------------------------------------------------------------------------
"$PY" -c 'from crop_sim_interfaces.msg import CropState; from crop_sim_interfaces.srv import Step; from crop_sim_interfaces.action import RunSeason' \
  || fail "crop_sim_interfaces was built but does not import in $PY"
echo "build_interfaces: crop_sim_interfaces installed into $VENV"
