#!/usr/bin/env bash
# Installs what is missing and builds the catkin workspace into .ws/ (build, devel, venv).
# Works on Debian 12 (ROS from Debian's own packages) and Ubuntu 20.04 with ROS Noetic.
# Usage: tools/bootstrap.sh [--with-cflib]     (idempotent; quick when nothing changed)
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
WS="$REPO/.ws"
WITH_CFLIB=0
for a in "$@"; do
  case "$a" in
    --with-cflib) WITH_CFLIB=1 ;;
    *) echo "bootstrap: unknown option $a" >&2; exit 2 ;;
  esac
done

# ROS tools run /usr/bin/python3; keep it (and system tools) first on PATH.
export PATH="/usr/bin:/bin:/usr/sbin:/sbin:$PATH"

say() { echo "[bootstrap] $*"; }

if [ -f /opt/ros/noetic/setup.bash ] || grep -q 'focal' /etc/os-release 2>/dev/null; then
  PLATFORM=noetic
  PKGS="ros-noetic-ros-base ros-noetic-rospy ros-noetic-rostest ros-noetic-tf2-ros ros-noetic-sensor-msgs
        ros-noetic-geometry-msgs ros-noetic-std-srvs ros-noetic-diagnostic-msgs ros-noetic-message-generation
        ros-noetic-message-runtime ros-noetic-robot-state-publisher ros-noetic-xacro python3-usb python3-numpy
        python3-yaml python3-pytest python3-matplotlib python3-venv python3-catkin-pkg"
else
  PLATFORM=debian
  PKGS="ros-base-dev python3-rospy python3-rostest python3-tf2-ros python3-usb python3-numpy python3-yaml
        python3-pytest python3-sensor-msgs python3-geometry-msgs python3-std-srvs python3-diagnostic-msgs
        ros-message-generation ros-robot-state-publisher python3-matplotlib python3-venv"
fi

missing=""
for p in $PKGS; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
if [ -n "$missing" ]; then
  say "installing:$missing"
  SUDO=""
  if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi
  if [ "$PLATFORM" = noetic ] && [ ! -f /etc/apt/sources.list.d/ros-latest.list ] && [ ! -f /opt/ros/noetic/setup.bash ]; then
    echo "ROS Noetic's apt source is not configured: see http://wiki.ros.org/noetic/Installation/Ubuntu" >&2
    exit 1
  fi
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq $missing >/dev/null
fi

if [ "$PLATFORM" = noetic ]; then
  set +u; source /opt/ros/noetic/setup.bash; set -u
fi

mkdir -p "$WS"
touch "$WS/CATKIN_IGNORE" "$WS/rospack_nosubdirs"

# A virtual environment that sees the system's ROS modules, for what Debian does not package.
VENV="$WS/venv"
if [ ! -x "$VENV/bin/python3" ]; then
  say "creating $VENV"
  /usr/bin/python3 -m venv --system-site-packages "$VENV"
fi
if [ "$PLATFORM" = debian ] && [ ! -x "$VENV/bin/xacro" ]; then
  say "installing xacro 1.13.3 (the ROS 1 line) into the venv"
  "$VENV/bin/pip" install -q --disable-pip-version-check "xacro==1.13.3"
fi

# The linter run by tools/run_tests.sh (configuration in ruff.toml), pinned so every machine agrees.
RUFF_VERSION=0.17.5
if ! "$VENV/bin/ruff" --version 2>/dev/null | grep -qx "ruff $RUFF_VERSION"; then
  say "installing ruff $RUFF_VERSION into the venv"
  "$VENV/bin/pip" install -q --disable-pip-version-check "ruff==$RUFF_VERSION"
fi

# The type checker run by tools/run_tests.sh (configuration in mypy.ini), pinned likewise: 1.16.1 is
# the last mypy that checks against Python 3.8 (Noetic's); later releases refuse python_version 3.8.
MYPY_VERSION=1.16.1
if ! "$VENV/bin/mypy" --version 2>/dev/null | grep -q "^mypy $MYPY_VERSION "; then
  say "installing mypy $MYPY_VERSION into the venv"
  "$VENV/bin/pip" install -q --disable-pip-version-check "mypy==$MYPY_VERSION"
fi

# cflib (Bitcraze's library) is an independent peer for the tests; it needs Python >= 3.10.
if [ "$WITH_CFLIB" = 1 ]; then
  CFVENV="$WS/cflib-venv"
  if /usr/bin/python3 -c 'import sys; sys.exit(0 if sys.version_info >= (3, 10) else 1)'; then
    if [ ! -x "$CFVENV/bin/python3" ] || ! "$CFVENV/bin/python3" -c 'import cflib' 2>/dev/null; then
      say "installing cflib 0.1.34 into $CFVENV"
      /usr/bin/python3 -m venv --system-site-packages "$CFVENV"
      "$CFVENV/bin/pip" install -q --disable-pip-version-check "cflib==0.1.34"
    fi
  else
    say "Python $(/usr/bin/python3 -V) is older than 3.10: cflib tests will be skipped"
  fi
fi

# Build. The repository root is the catkin source space.
export PATH="/usr/bin:/bin:$PATH:$VENV/bin"
say "building the catkin workspace in $WS"
cd "$WS"
if ! catkin_make --source "$REPO" -DPYTHON_EXECUTABLE=/usr/bin/python3 -DCATKIN_ENABLE_TESTING=ON \
      > "$WS/build.log" 2>&1; then
  tail -n 40 "$WS/build.log" >&2
  echo "bootstrap: catkin_make failed (full log: $WS/build.log)" >&2
  exit 1
fi
say "workspace ready: source $WS/devel/setup.bash"
