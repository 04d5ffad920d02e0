#!/usr/bin/env bash
# The same flights per world pacing mode, with the real-time factor the world ran at, on the world's
# truth: hover_vicon.test (one Crazyflie, hover RMS of the true position over 5 s of world time after
# settling), the chapter demo (tools/run_demo.sh's sim_mission.launch: two Crazyflies, hold RMS at the
# waypoints) and the swarm demo (tools/run_demo.sh --swarm's swarm.launch: figure-8 mean tracking
# error) at 9 and at 49 Crazyflies. Default modes: speed 1 on an idle machine, auto with two busy loops.
# MODES="1.0:4 auto:4" (speed:busy loops) and OUT_FILE=... choose other modes and another table.
# Usage: bench/bench_simtime.sh [flight ...]   (flights: hover_vicon multi_hover_vrpn (rostests),
# chapter, swarm9, swarm49; default: hover_vicon chapter swarm9 swarm49; after tools/bootstrap.sh; on a
# machine shared with other ROS users give it their lock: LOCK=/tmp/ros.lock bench/bench_simtime.sh, and it
# takes the lock for each run, busy loops included, and releases it between runs).
# Writes bench/results/simtime.txt.
set -uo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$REPO/tools/env.sh"
FLIGHTS="${*:-hover_vicon chapter swarm9 swarm49}"
OUT="${RUN_DIR:-$(mktemp -d)}"
export ROS_LOG_DIR="$OUT/ros_log" ROS_HOME="$OUT/ros_home" PYTHONUNBUFFERED=1
RESULT="${OUT_FILE:-$REPO/bench/results/simtime.txt}"
MODES="${MODES:-1.0:0 auto:2}"
[ -n "${ONE_RUN:-}" ] || {
  echo "The same flights per world pacing mode (chapter controller or onboard high-level commander,"
  echo "crazyflie_server, fake radio, simulated world under /use_sim_time); busy: shell busy loops"
  echo "('while :; do :; done') running alongside. RTF: the world's real-time factor (world s per wall s):"
  echo "hover_vicon: on /diagnostics after the hold; the demos: their summary's average over the flight."
  echo "speed: hover_vicon: the speed auto had chosen at the end; the demos: the setting. Errors on the"
  echo "world's true state. load: the 1-min load average before the run (jobs outside the lock included)."
  echo "Machine: $(nproc) cores, $(uname -sr), $(/usr/bin/python3 -V 2>&1). $(date -u +%Y-%m-%d)."
  printf "%-12s %-11s %-5s %-11s %-22s %-8s %-6s %-6s %-5s %s\n" flight mode busy vehicle figure value RTF speed wall "result / load before"
} > "$OUT/table.txt"
field() { echo "$1" | sed -n "s/.*'$2': '\([0-9.]*\)'.*/\1/p"; }
row() { printf "%-12s %-11s %-5s %-11s %-22s %-8s %-6s %-6s %-5s %s\n" "$@" >> "$OUT/table.txt"; }
pace() {  # "world ran at 0.93x real time on average (speed auto, 120 s wall clock)" -> "0.93 auto"
  sed -n 's/.*world ran at \([0-9.]*\)x real time on average (speed \([^,]*\),.*/\1 \2/p' "$1" | tail -1
}
if [ -n "${ONE_RUN:-}" ]; then FLIGHTS=${ONE_RUN%% *} MODES=${ONE_RUN##* }; fi
for f in $FLIGHTS; do
  for mode in $MODES; do
    if [ -z "${ONE_RUN:-}" ] && [ -n "${LOCK:-}" ]; then   # one run per hold of the lock
      ONE_RUN="$f $mode" RUN_DIR="$OUT" flock "$LOCK" "$0"
      continue
    fi
    speed=${mode%%:*} hogs=${mode##*:}
    load="load $(cut -d' ' -f1 /proc/loadavg)"
    P=""
    for _ in $(seq 1 "$hogs"); do bash -c 'while :; do :; done' & P="$P $!"; done
    start=$(date +%s)
    log="$OUT/$f-$speed-$hogs.log"
    export CRAZYFLIE_SIM_SPEED=$speed
    case "$f" in
      chapter)
        roslaunch --screen -p 11411 crazyflie_demo sim_mission.launch plot:="$OUT/$f-$speed-$hogs.png" \
          result_file:="$OUT/result.txt" > "$log" 2>&1
        rc=$(cat "$OUT/result.txt" 2>/dev/null || echo "no result") ;;
      swarm*)
        rm -f "$OUT/stats.json"
        roslaunch --screen -p 11411 crazyflie_demo swarm.launch sim:=true monitor:=true n:="${f#swarm}" \
          plot:="$OUT/$f-$speed-$hogs.png" stats_file:="$OUT/stats.json" > "$log" 2>&1
        rc=$(sed -n 's/^swarm: result: //p' "$log" | tail -1) ;;
      *)
        rostest --text crazyflie_demo "$f.test" > "$log" 2>&1
        rc="rostest rc $?" ;;
    esac
    wall=$(( $(date +%s) - start ))
    [ -n "$P" ] && kill $P
    wait 2>/dev/null
    case "$f" in
      chapter)
        read -r rtf sp <<< "$(pace "$log")"
        grep -E '^crazyflie[0-9]* +[0-9]+/[0-9]+ ' "$log" | while read -r name wp _ rms _; do
          row "$f" "speed $speed" "$hogs" "$name" "hold RMS [mm] ($wp wp)" \
            "$(awk -v v="$rms" 'BEGIN{printf "%.0f", v*1000}')" "$rtf" "$sp" "$wall" "$rc; $load"
        done ;;
      swarm*)
        read -r rtf sp <<< "$(pace "$log")"
        fig=$(/usr/bin/python3 -c "import json,sys; s=json.load(open(sys.argv[1]))['phases']['figure8']; \
print('%.2f %.2f %s %.2f' % (100*s['mean'], 100*s['worst_mean'], s['worst'], 100*s['max']))" "$OUT/stats.json" 2>/dev/null)
        if [ -n "$fig" ]; then
          read -r mean worst wname max <<< "$fig"
          row "$f" "speed $speed" "$hogs" "all ${f#swarm}" "figure-8 mean [cm]" "$mean" "$rtf" "$sp" "$wall" "$rc; $load"
          row "$f" "speed $speed" "$hogs" "$wname" "worst CF mean [cm]" "$worst" "$rtf" "$sp" "$wall" ""
          row "$f" "speed $speed" "$hogs" "all ${f#swarm}" "largest error [cm]" "$max" "$rtf" "$sp" "$wall" ""
        fi ;;
      *)
        world=$(grep -m1 -o "WORLD .*" "$log")
        grep -o "HOVER .*" "$log" | while read -r _ name rest; do
          rms=$(echo "$rest" | sed -n 's/.*rms=\([0-9.]*\).*/\1/p')
          row "$f" "speed $speed" "$hogs" "$name" "hover RMS [mm]" "$(awk -v v="$rms" 'BEGIN{printf "%.2f", v*1000}')" \
            "$(field "$world" "real-time factor")" "$(field "$world" speed)" "$wall" "$rc; $load"
        done ;;
    esac
    grep -q "^$f .*speed $speed  *$hogs " "$OUT/table.txt" \
      || echo "$f speed $speed busy $hogs: no figures ($rc), log $log" >> "$OUT/table.txt"
  done
done
[ -z "${ONE_RUN:-}" ] || exit 0
echo "Run: LOCK=/tmp/ros.lock MODES='$MODES' bench/bench_simtime.sh $*" >> "$OUT/table.txt"
cat "$OUT/table.txt" | tee "$RESULT"
echo "logs: $OUT"
