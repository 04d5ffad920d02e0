# Source this file to use the built workspace: ROS environment, devel space, the venv's tools (xacro).
# It keeps /usr/bin/python3 (the interpreter ROS runs) first on PATH.
_cf_repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export PATH="/usr/bin:/bin:$PATH:$_cf_repo/.ws/venv/bin"
if [ -f /opt/ros/noetic/setup.bash ]; then set +u; source /opt/ros/noetic/setup.bash; fi
set +u
source "$_cf_repo/.ws/devel/setup.bash"
unset _cf_repo
