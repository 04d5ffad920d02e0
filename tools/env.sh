# Source this file to use the built workspace: ROS environment, devel space, the venv's tools (xacro).
# It keeps /usr/bin/python3 (the interpreter ROS runs) first on PATH.
_cf_repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export PATH="/usr/bin:/bin:$PATH:$_cf_repo/.ws/venv/bin"
if [ -f /opt/ros/noetic/setup.bash ]; then set +u; source /opt/ros/noetic/setup.bash; fi
set +u
source "$_cf_repo/.ws/devel/setup.bash"
unset _cf_repo
# ROS 1 listens on every interface by default: anyone on the network could then call emergency,
# update_params or publish cmd_vel. Unless the user chose an address (ROS_IP / ROS_HOSTNAME) or a
# master on another machine, bind this shell's ROS processes (master included) to loopback. For
# real hardware across machines: export ROS_IP=<this machine's address> (see the README).
case "${ROS_MASTER_URI:-http://localhost:11311}" in
  http://localhost:*|http://127.*) _cf_local_master=1 ;;
  *) _cf_local_master=0 ;;
esac
if [ -z "${ROS_IP:-}" ] && [ -z "${ROS_HOSTNAME:-}" ] && [ "$_cf_local_master" = 1 ]; then
  export ROS_IP=127.0.0.1
fi
unset _cf_local_master
