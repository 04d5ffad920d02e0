#!/usr/bin/env bash
# Flight figures of the simulated stack (real server, fake radio, position controller):
# hover hold error (RMS / max over 5 s after settling), waypoint times per Crazyflie,
# emergency and lost-pose reactions, and the main job's mission summary and duration.
# Usage: bench/bench_flight.sh   (after tools/bootstrap.sh; about 2.5 minutes)
set -uo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$REPO/tools/env.sh"
OUT="$(mktemp -d)"
export ROS_LOG_DIR="$OUT/ros_log"
echo "machine: $(nproc) cores, $(uname -sr), $(/usr/bin/python3 -V)"
for t in hover_vicon hover_vrpn multi_hover multi_waypoint emergency lost_pose teleop; do
  start=$(date +%s)
  rostest --text crazyflie_demo "$t.test" > "$OUT/$t.log" 2>&1
  rc=$?
  echo "== $t.test (rc $rc, $(( $(date +%s) - start )) s wall clock)"
  grep -E "^(HOVER|WAYPOINTS|MISSION|EMERGENCY|LOST_POSE|TELEOP)" "$OUT/$t.log" | sed 's/^/  /'
done
echo "== tools/run_demo.sh (main job)"
start=$(date +%s)
CRAZYFLIE_OUT="$OUT/demo" "$REPO/tools/run_demo.sh" > "$OUT/demo.log" 2>&1
rc=$?
sed -n '/=== mission summary ===/,/^plot:/p' "$OUT/demo.log" | sed 's/^/  /'
echo "  exit code $rc, $(( $(date +%s) - start )) s wall clock (including the workspace check)"
