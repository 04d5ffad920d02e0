#!/usr/bin/env bash
# The main job: installs what is missing, builds the workspace, then flies the chapter's
# multi-waypoint scenario with two simulated Crazyflies on one fake Crazyradio, headless.
# Prints progress, a summary per Crazyflie, and the path of a PNG plot of the flight.
# tools/run_demo.sh --swarm [n:=9 ...]: instead, 49 simulated Crazyflies on three fake Crazyradios
# fly the swarm demo (takeoff, figure-8, formation change, land, all by the onboard high-level
# commander) headless; prints a summary line per phase and writes a plot of the paths seen from
# above and of the tracking error per Crazyflie against the plan, on the world's truth.
set -euo pipefail
SWARM=0
if [ "${1:-}" = "--swarm" ]; then SWARM=1; shift; fi
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$REPO/tools/bootstrap.sh"
source "$REPO/tools/env.sh"
OUT="${CRAZYFLIE_OUT:-$REPO/out}"
mkdir -p "$OUT"
export ROS_LOG_DIR="$OUT/ros_log"
RESULT="$OUT/mission_result.txt"
rm -f "$RESULT"
start=$(date +%s)
export PYTHONUNBUFFERED=1
if [ "$SWARM" = 1 ]; then
  RESULT="$OUT/swarm_result.txt"
  rm -f "$RESULT"
  roslaunch --screen -p "${ROS_PORT:-11411}" crazyflie_demo swarm.launch sim:=true monitor:=true \
    plot:="$OUT/crazyflie_swarm.png" result_file:="$RESULT" "$@" 2>&1 \
    | grep --line-buffered -v '^ \* /' || true
  result="$(cat "$RESULT" 2>/dev/null || echo "no result (the swarm monitor did not finish)")"
  echo "swarm: $result ($(( $(date +%s) - start )) s wall clock); plot: $OUT/crazyflie_swarm.png"
  [ "$result" = ok ]
  exit
fi
# roslaunch lists every parameter (about 200 lines) before it starts: drop that list from the
# console, keep everything else as it comes (unbuffered, so progress lines appear at once).
# The mission monitor is a required node: when it is done, roslaunch shuts the rest down and
# says so in red ("REQUIRED process ... has died"); the last line below tells the outcome.
export PYTHONUNBUFFERED=1
roslaunch --screen -p "${ROS_PORT:-11411}" crazyflie_demo sim_mission.launch \
  plot:="$OUT/crazyflie_mission.png" result_file:="$RESULT" "$@" 2>&1 \
  | grep --line-buffered -v '^ \* /' || true
result="$(cat "$RESULT" 2>/dev/null || echo "no result (the mission monitor did not finish)")"
echo "mission: $result ($(( $(date +%s) - start )) s wall clock)"
[ "$result" = ok ]
