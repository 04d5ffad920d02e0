#!/usr/bin/env bash
# The main job: installs what is missing, builds the workspace, then flies the chapter's
# multi-waypoint scenario with two simulated Crazyflies on one fake Crazyradio, headless.
# Prints progress, a summary per Crazyflie, and the path of a PNG plot of the flight.
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$REPO/tools/bootstrap.sh"
source "$REPO/tools/env.sh"
OUT="${CRAZYFLIE_OUT:-$REPO/out}"
mkdir -p "$OUT"
export ROS_LOG_DIR="$OUT/ros_log"
RESULT="$OUT/mission_result.txt"
rm -f "$RESULT"
start=$(date +%s)
roslaunch --screen -p "${ROS_PORT:-11411}" crazyflie_demo sim_mission.launch \
  plot:="$OUT/crazyflie_mission.png" result_file:="$RESULT" "$@" || true
result="$(cat "$RESULT" 2>/dev/null || echo "no result (the mission monitor did not finish)")"
echo "mission: $result ($(( $(date +%s) - start )) s wall clock)"
[ "$result" = ok ]
