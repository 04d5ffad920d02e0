#!/usr/bin/env bash
# Hover error per world pacing mode, with the real-time factor the world ran at: hover_vicon.test
# (one Crazyflie) and multi_hover_vrpn.test (two, VRPN motion capture), RMS / max of the true position
# over 5 s of world time after settling, in three modes: speed 1 on an idle machine, speed 1 with two
# busy loops, auto with two busy loops.
# MODES="1.0:4 auto:4" (speed:busy loops) and OUT_FILE=... choose other modes and another table.
# Usage: bench/bench_simtime.sh [test ...]   (default: hover_vicon multi_hover_vrpn; after
# tools/bootstrap.sh; on a machine shared with other ROS users run it under their lock:
# flock /tmp/ros.lock bench/bench_simtime.sh). Writes bench/results/simtime.txt.
set -uo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$REPO/tools/env.sh"
TESTS="${*:-hover_vicon multi_hover_vrpn}"
OUT="$(mktemp -d)"
export ROS_LOG_DIR="$OUT/ros_log" ROS_HOME="$OUT/ros_home"
RESULT="${OUT_FILE:-$REPO/bench/results/simtime.txt}"
MODES="${MODES:-1.0:0 1.0:2 auto:2}"
{
  echo "Hover error per world pacing mode (crazyflie_demo rostests: chapter controller, crazyflie_server, fake"
  echo "radio, simulated world under /use_sim_time); busy: 'yes > /dev/null' loops running alongside. RTF: the"
  echo "world's real-time factor (world s per wall s) on /diagnostics after the hold; speed: where the world"
  echo "was set then; lag: auto's host run-queue wait per time slice [ms]. Errors on the world's true state."
  echo "Machine: $(nproc) cores, $(uname -sr), $(/usr/bin/python3 -V 2>&1). $(date -u +%Y-%m-%d)."
  printf "%-18s %-11s %-5s %-12s %-9s %-9s %-6s %-6s %-5s %-5s\n" test mode busy vehicle "rms[mm]" "max[mm]" RTF speed lag "wall"
} > "$OUT/table.txt"
field() { echo "$1" | sed -n "s/.*'$2': '\([0-9.]*\)'.*/\1/p"; }
for t in $TESTS; do
  for mode in $MODES; do
    speed=${mode%%:*} hogs=${mode##*:}
    P=""
    for _ in $(seq 1 "$hogs"); do yes > /dev/null & P="$P $!"; done
    start=$(date +%s)
    CRAZYFLIE_SIM_SPEED=$speed rostest --text crazyflie_demo "$t.test" > "$OUT/run.log" 2>&1
    rc=$?
    wall=$(( $(date +%s) - start ))
    [ -n "$P" ] && kill $P
    cp "$OUT/run.log" "$OUT/$t-$speed-$hogs.log"
    world=$(grep -m1 -o "WORLD .*" "$OUT/run.log")
    grep -o "HOVER .*" "$OUT/run.log" | while read -r _ name rest; do
      rms=$(echo "$rest" | sed -n 's/.*rms=\([0-9.]*\).*/\1/p')
      max=$(echo "$rest" | sed -n 's/.*max=\([0-9.]*\).*/\1/p')
      printf "%-18s %-11s %-5s %-12s %-9s %-9s %-6s %-6s %-5s %-5s%s\n" "$t" "speed $speed" "$hogs" "$name" \
        "$(awk -v v="$rms" 'BEGIN{printf "%.2f", v*1000}')" "$(awk -v v="$max" 'BEGIN{printf "%.2f", v*1000}')" \
        "$(field "$world" "real-time factor")" "$(field "$world" speed)" \
        "$(field "$world" "host run-queue wait \[ms\]")" "$wall" "$([ $rc = 0 ] || echo "  rostest rc $rc")"
    done >> "$OUT/table.txt"
    grep -q "HOVER" "$OUT/run.log" || echo "$t speed $speed busy $hogs: no HOVER line (rc $rc), log $OUT/$t-$speed-$hogs.log" >> "$OUT/table.txt"
  done
done
cat "$OUT/table.txt" | tee "$RESULT"
echo "logs: $OUT"
