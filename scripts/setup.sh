#!/usr/bin/env bash
# Sets up the woody workspace from nothing: venv, pinned PyPI packages (ROS 2
# Jazzy wheels included), the CMake export fix, the interface packages (woody_msgs,
# tf2_msgs, foxglove_msgs) built with colcon into the venv, and the Python
# packages installed editable. Every step is
# skipped when its inputs have not changed, so a second call takes seconds.
# Used by `make setup` and by docker/Dockerfile (the one place the steps live).
#
#   scripts/setup.sh [VENV_DIR]        (default: .venv beside this repo)
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd)
VENV=${1:-${WOODY_VENV:-$ROOT/.venv}}
mkdir -p "$(dirname "$VENV")" && VENV=$(cd "$(dirname "$VENV")" && pwd)/$(basename "$VENV")
PYTHON=${PYTHON:-python3.11}
command -v "$PYTHON" >/dev/null 2>&1 || PYTHON=python3
STAMPS=$VENV/.woody-stamps

log() { printf '[setup] %s\n' "$*"; }
digest() { cat "$@" | sha256sum | cut -c1-16; }
is_current() { [ -f "$STAMPS/$1" ] && [ "$(cat "$STAMPS/$1")" = "$2" ]; }
mark() { mkdir -p "$STAMPS"; echo "$2" > "$STAMPS/$1"; }

start=$(date +%s)

# 1. Virtual environment with Python 3.11 (the ROS wheels are cp311).
if [ ! -x "$VENV/bin/python" ]; then
  version=$("$PYTHON" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
  [ "$version" = "3.11" ] || { echo "[setup] error: Python 3.11 is required (found $PYTHON = $version)" >&2; exit 1; }
  log "creating $VENV"
  "$PYTHON" -m venv "$VENV"
fi
PIP=("$VENV/bin/python" -m pip --disable-pip-version-check -q)

# 2. Pinned dependencies.
req=$(digest "$ROOT/requirements.txt")
if ! is_current requirements "$req"; then
  log "installing pinned packages (ROS 2 Jazzy wheels, pybullet, OpenCV, MCAP, ...)"
  "${PIP[@]}" install --upgrade pip
  "${PIP[@]}" install -r "$ROOT/requirements.txt"
  "$VENV/bin/python" "$ROOT/scripts/patch_ros_cmake.py"
  mark requirements "$req"
  rm -f "$STAMPS/woody_msgs"
fi

# 3. Environment every Python process of the venv gets (nodes, tests, users' own scripts):
#    the project's Fast DDS profile and the ament prefix, unless the user set them.
cat > "$VENV/lib/python3.11/site-packages/woody_ros_env.pth" <<EOF
import os; os.environ.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE', '$ROOT/config/fastdds.xml'); os.environ.setdefault('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp'); os.environ.setdefault('AMENT_PREFIX_PATH', '$VENV')
EOF

# 4. The interface packages: woody_msgs, and the subsets of tf2_msgs and foxglove_msgs (built from their
#    public definitions; no wheel exists), built by colcon in ros_ws/ and installed into the venv so that
#    their Python modules and libraries are found with no `source` step.
INTERFACES=("$ROOT/src/woody_msgs" "$ROOT/ros_ws/src/tf2_msgs" "$ROOT/ros_ws/src/foxglove_msgs")
msgs=$(digest $(for package in "${INTERFACES[@]}"; do find "$package" -type f | sort; done))
if ! is_current interfaces "$msgs"; then
  log "building woody_msgs, tf2_msgs and foxglove_msgs with colcon"
  (
    cd "$ROOT/ros_ws" && mkdir -p log
    export PATH="$VENV/bin:$PATH" AMENT_PREFIX_PATH="$VENV" CMAKE_PREFIX_PATH="$VENV"
    "$VENV/bin/colcon" --log-base log build \
      --base-paths "${INTERFACES[@]}" --build-base build --install-base "$VENV" --merge-install \
      --cmake-args -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$VENV/bin/python" > "$ROOT/ros_ws/log/build-interfaces.txt" 2>&1 || { cat "$ROOT/ros_ws/log/build-interfaces.txt" >&2; exit 1; }
  )
  mark interfaces "$msgs"
fi

# 5. The Python packages, editable so source edits take effect at once.
PY_PACKAGES=(woody_common woody_sim woody_vision woody_bag woody_experiments woody_tools)
setups=() editables=()
for package in "${PY_PACKAGES[@]}"; do
  setups+=("$ROOT/src/$package/setup.py")
  editables+=(-e "$ROOT/src/$package")
done
py=$(digest "${setups[@]}")
if ! is_current python_packages "$py$ROOT"; then
  log "installing ${PY_PACKAGES[*]} (editable)"
  "${PIP[@]}" install --no-deps --no-build-isolation "${editables[@]}" \
    > "$STAMPS/pip-editable.log" 2>&1 || { cat "$STAMPS/pip-editable.log" >&2; exit 1; }
  mark python_packages "$py$ROOT"
fi

log "ready in $(( $(date +%s) - start )) s: entry points are in $VENV/bin"
