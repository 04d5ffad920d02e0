#!/usr/bin/env bash
# Runs the README's test command (tools/run_tests.sh) N times in a row with one core kept busy by
# a busy loop, the way a shared CI machine is busy, and prints one line per run:
#   run 1/5: ok   612 passed, 0 failed   512 s
#   run 2/5: FAIL 611 passed, 1 failed   530 s   failed: crazyflie_demo/multi_hover.test
# then a last line "soak: K of N runs green". Each run's full output is kept in
# .ws/soak/run-<i>.log. Extra arguments go to tools/run_tests.sh (and so to pytest).
#
#   tools/soak.sh [-n N] [--hogs H] [--lock FILE] [-- run_tests.sh arguments]
#
# The ROS parts of the suite use fixed ports: on a machine shared with other ROS users, give
# their lock file with --lock (e.g. --lock /tmp/ros.lock); each run then takes it (flock) for its
# own duration only, and the busy loops run only while it is held.
set -uo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
runs=5
hogs=1
lock=""
while [ $# -gt 0 ]; do
  case "$1" in
    -n) runs="${2:?-n needs a number}"; shift 2 ;;
    --hogs) hogs="${2:?--hogs needs a number}"; shift 2 ;;
    --lock) lock="${2:?--lock needs a file}"; shift 2 ;;
    --) shift; break ;;
    -h|--help) sed -n '2,13p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) break ;;
  esac
done
case "$runs$hogs" in *[!0-9]*) echo "soak: -n and --hogs take whole numbers" >&2; exit 2 ;; esac

LOGS="$REPO/.ws/soak"
mkdir -p "$LOGS"
hog_pids=()
stop_hogs() {
  for p in "${hog_pids[@]:-}"; do [ -n "$p" ] && kill "$p" 2>/dev/null; done
  hog_pids=()
}
trap 'stop_hogs; exit 130' INT TERM
trap stop_hogs EXIT

RESULTS="$REPO/.ws/test_results"
green=0
for i in $(seq 1 "$runs"); do
  if [ -n "$lock" ]; then
    exec {lock_fd}>>"$lock"
    flock "$lock_fd"
  fi
  for _ in $(seq 1 "$hogs"); do
    /usr/bin/python3 -c 'while True: pass' &
    hog_pids+=("$!")
  done
  start=$(date +%s)
  "$REPO/tools/run_tests.sh" "$@" > "$LOGS/run-$i.log" 2>&1
  rc=$?
  took=$(( $(date +%s) - start ))
  stop_hogs
  [ -n "$lock" ] && exec {lock_fd}>&-
  counts="$(grep -E '^[0-9]+ passed, [0-9]+ failed$' "$LOGS/run-$i.log" | tail -n 1)"
  failed="$(grep -E '^FAIL ' "$LOGS/run-$i.log" | awk '{print $2}' | tr '\n' ' ')"
  py_failed="$(/usr/bin/python3 - "$RESULTS/pytest.xml" <<'PY'
import sys, xml.etree.ElementTree as ET
try:
    root = ET.parse(sys.argv[1]).getroot()
except Exception:
    sys.exit(0)
bad = [c for c in root.iter("testcase") if c.find("failure") is not None or c.find("error") is not None]
print(" ".join("%s::%s" % (c.get("classname", ""), c.get("name", "")) for c in bad))
PY
)"
  if [ "$rc" -eq 0 ]; then
    green=$((green + 1)); verdict="ok  "
  else
    verdict="FAIL"
  fi
  line="run $i/$runs: $verdict ${counts:-no summary (see $LOGS/run-$i.log)}   $took s"
  [ -n "$failed$py_failed" ] && line="$line   failed: $failed$py_failed"
  echo "$line"
done
echo "soak: $green of $runs runs green (one busy loop per --hogs, here $hogs; logs in $LOGS)"
[ "$green" -eq "$runs" ]
