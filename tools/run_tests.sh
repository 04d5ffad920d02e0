#!/usr/bin/env bash
# Runs every test of the stack on a fresh machine: installs what is missing, builds the
# workspace, then runs the linter, the type checker, the pytest unit tests and every rostest launch file
# (simulated Crazyflies, no hardware). Ends with one summary line "N passed, N failed"
# (the lint counts as one check, the type check another). Extra arguments go to pytest.
#
# pytest and the rostests run side by side, CRAZYFLIE_TEST_JOBS (default 3) at a time, the longest
# first (expected seconds in tools/test_durations.txt), so the run ends on short tests. Most
# rostests wait on simulated flight time rather than compute, so a two-core machine carries three.
# A job beyond the first starts only while the machine has room for it: CRAZYFLIE_TEST_IDLE_CORES
# (default 0.6) of its cores idle over the last second, and at least the cores the job is expected to
# use (its CPU over its wall seconds in tools/test_durations.txt); and the cores the running jobs are
# expected to use, with it, leave that margin free. Flight figures do not depend on this (the
# simulated worlds run on ROS time and slow down under load: docs/testing.md), but a world slowed
# down stretches its test in wall time, and rostest's time-limit counts wall seconds. A job that must
# wait lets later jobs of the queue start first if they fit. On a machine busy with other work the
# run takes longer instead (the summary says how long starts were held back).
# The rostests are isolated from each other: each has its own master (rostest picks a free port)
# and its own world address and ports (test_rostest_ports.py holds that). One line per test as it
# ends: "PASS <pkg>/<file>.test (<wall> s, CPU <cpu> s)" or FAIL with what rostest reported of the
# failure and the log's tail, and the summary names each failure's exception ("why <id>: ...");
# logs, the pytest output and the measured durations (durations.txt) are in .ws/test_results/.
# CRAZYFLIE_ROSTESTS="driver_single.test hover_vicon.test" runs only those rostests ("none": none).
set -uo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$REPO/tools/bootstrap.sh" --with-cflib || { echo "0 passed, 1 failed"; exit 1; }
source "$REPO/tools/env.sh"
cd "$REPO"

JOBS="${CRAZYFLIE_TEST_JOBS:-3}"
case "$JOBS" in ''|*[!0-9]*|0) echo "CRAZYFLIE_TEST_JOBS must be a whole number >= 1, got '$JOBS'" >&2; exit 2 ;; esac
IDLE_CORES="${CRAZYFLIE_TEST_IDLE_CORES:-0.6}"
case "$IDLE_CORES" in ''|*[!0-9.]*|*.*.*|.) echo "CRAZYFLIE_TEST_IDLE_CORES must be a number of cores >= 0, got '$IDLE_CORES'" >&2
  exit 2 ;; esac
RESULTS="$REPO/.ws/test_results"
rm -rf "$RESULTS"; mkdir -p "$RESULTS/jobs"
export ROS_LOG_DIR="$RESULTS/ros_log"
export CRAZYFLIE_TOC_CACHE="$RESULTS/toc_cache"     # written atomically: concurrent writers are safe

echo "== lint (ruff, settings in ruff.toml) =="
if "$REPO/.ws/venv/bin/ruff" check --no-cache "$REPO"; then lint_pass=1; lint_fail=0; else lint_pass=0; lint_fail=1; fi
echo "== types (mypy, settings in mypy.ini) =="
if (cd "$REPO" && "$REPO/.ws/venv/bin/mypy" ); then types_pass=1; types_fail=0; else types_pass=0; types_fail=1; fi

# The jobs: "pytest" and every rostest as <pkg>/<file>.test.
rostests=()
for t in $(ls crazyflie_*/test/rostest/*.test 2>/dev/null | sort); do
  id="${t%%/*}/$(basename "$t")"
  if [ -n "${CRAZYFLIE_ROSTESTS+set}" ]; then
    case " $CRAZYFLIE_ROSTESTS " in *" $(basename "$t") "*|*" $id "*) ;; *) continue ;; esac
  fi
  rostests+=("$id")
done

# Longest first; a job without a recorded duration counts as 60 s.
expected() {
  awk -v id="$1" '$1 !~ /^#/ && $3 == id { print $1; found = 1; exit } END { if (!found) print 60 }' \
    "$REPO/tools/test_durations.txt" 2>/dev/null || echo 60
}
# Cores a job is expected to use: CPU over wall seconds as recorded; 0.5 when not recorded.
declare -A cores_of
for id in pytest "${rostests[@]}"; do
  cores_of[$id]="$(awk -v id="$id" '$1 !~ /^#/ && $3 == id && $2 ~ /^[0-9]+$/ && $1 > 0 {
      printf "%.2f", $2 / $1; found = 1; exit } END { if (!found) print 0.5 }' \
    "$REPO/tools/test_durations.txt" 2>/dev/null || echo 0.5)"
done
queue=()
while read -r _ id; do queue+=("$id"); done < <(
  for id in pytest "${rostests[@]}"; do echo "$(expected "$id") $id"; done | sort -k1,1nr -k2,2)

log_of() {
  case "$1" in pytest) echo "$RESULTS/pytest.log" ;; *) echo "$RESULTS/rostest_${1%%/*}_${1#*/}.log" ;; esac
}
key_of() { echo "${1//\//_}"; }

# Each job runs in its own process group (job control on), so stopping the run stops its whole tree.
set -m
declare -A pid_of start_of
running=()
stop_all() {
  for id in "${running[@]:-}"; do
    [ -n "$id" ] || continue
    pkill -TERM -P "${pid_of[$id]}" 2>/dev/null; kill -TERM -- "-${pid_of[$id]}" 2>/dev/null
  done
}
trap 'stop_all; exit 130' INT TERM

start_job() {
  local id="$1" key; key="$(key_of "$1")"
  if [ "$id" = pytest ]; then
    set -- /usr/bin/python3 -m pytest -q -rs --junitxml="$RESULTS/pytest.xml" "${PYTEST_ARGS[@]}"
  else
    set -- timeout 600 rostest "${id%%/*}" "${id#*/}"
  fi
  ( "$@" > "$(log_of "$id")" 2>&1 < /dev/null
    rc=$?
    times > "$RESULTS/jobs/$key.cpu"
    echo "$rc" > "$RESULTS/jobs/$key.tmp" && mv "$RESULTS/jobs/$key.tmp" "$RESULTS/jobs/$key.rc" ) &
  pid_of[$id]=$!
  start_of[$id]=$(date +%s)
  running+=("$id")
}

# CPU of the job's processes: the children's line of `times` ("0m12.345s 0m1.234s"), user + sys seconds
cpu_seconds() {
  awk 'NR == 2 { s = 0; for (i = 1; i <= 2; i++) { split($i, p, "m"); sub("s", "", p[2]); s += p[1] * 60 + p[2] } printf "%.0f", s }' "$1"
}

# What rostest reported for each failed or erroring test case: its block from "[...][FAILURE]" or
# "[...][ERROR]" to the dashed line that closes it (at most 30 lines); the log's last 40 if none.
failure_of() {
  awk '/\]\[(FAILURE|ERROR)\]-*$/ { on = 1; n = 0 } on && n < 30 { print; n++; found = 1 }
       on && /^--------------------+$/ { on = 0 } END { exit !found }' "$1" || tail -n 40 "$1"
}
# The first line of the last of those blocks (rostest puts the exception's message there), for the summary.
reason_of() {
  failure_of "$1" | awk 'take { print; take = 0 } /\]\[(FAILURE|ERROR)\]-*$/ { take = 1 }' | tail -n 1 | cut -c1-400
}

ros_pass=0; ros_fail=0; failed=""; pytest_rc=1
finish_job() {
  local id="$1" key rc took cpu; key="$(key_of "$1")"
  wait "${pid_of[$id]}" 2>/dev/null
  rc="$(cat "$RESULTS/jobs/$key.rc")"
  took=$(( $(date +%s) - ${start_of[$id]} ))
  cpu="$(cpu_seconds "$RESULTS/jobs/$key.cpu")"
  echo "$took $cpu $id" >> "$RESULTS/durations.txt"
  if [ "$id" = pytest ]; then
    pytest_rc="$rc"
    echo "== unit tests (pytest, $took s, CPU $cpu s) =="
    cat "$RESULTS/pytest.log"
  elif [ "$rc" -eq 0 ]; then
    ros_pass=$((ros_pass + 1)); echo "PASS $id ($took s, CPU $cpu s)"
  else
    ros_fail=$((ros_fail + 1)); failed="$failed $id"
    echo "FAIL $id ($took s, CPU $cpu s)"
    failure_of "$(log_of "$id")" | sed 's/^/    /'
    echo "    -- the log's last 20 lines --"
    tail -n 20 "$(log_of "$id")" | sed 's/^/    /'
  fi
}

# Idle cores over the last second, from /proc/stat's jiffies ("idle iowait" and the total of all
# fields of its first line), sampled every pass of the loop below; 0 until two samples exist.
cpu_samples=()
sample_cpu() {
  cpu_samples+=("$(awk '/^cpu / { t = 0; for (i = 2; i <= NF; i++) t += $i; print $5 + $6, t; exit }' /proc/stat)")
  [ "${#cpu_samples[@]}" -le 3 ] || cpu_samples=("${cpu_samples[@]:1}")
}
idle_cores() {
  [ "${#cpu_samples[@]}" -ge 2 ] || { echo 0; return; }
  awk -v a="${cpu_samples[0]}" -v b="${cpu_samples[${#cpu_samples[@]}-1]}" -v n="$(getconf _NPROCESSORS_ONLN)" \
    'BEGIN { split(a, x, " "); split(b, y, " "); d = y[2] - x[2]; printf "%.2f", (d > 0 ? n * (y[1] - x[1]) / d : 0) }'
}
pick_job() {      # the index in the queue of the first job there is room for (see the top), or -1
  [ "${#running[@]}" -eq 0 ] && { echo 0; return; }
  local id reserved="" queued=""
  for id in "${running[@]}"; do reserved="$reserved ${cores_of[$id]:-0.5}"; done
  for id in "${queue[@]}"; do queued="$queued ${cores_of[$id]:-0.5}"; done
  awk -v idle="$(idle_cores)" -v margin="$IDLE_CORES" -v reserved="$reserved" -v queued="$queued" \
      -v n="$(getconf _NPROCESSORS_ONLN)" 'BEGIN {
    r = 0; k = split(reserved, a, " "); for (i = 1; i <= k; i++) r += a[i]
    k = split(queued, q, " ")
    for (i = 1; i <= k; i++) { need = (q[i] > margin ? q[i] : margin)
      if (idle >= need && r + q[i] <= n - margin) { print i - 1; exit } }
    print -1 }'
}

PYTEST_ARGS=("$@")
echo "== unit tests (pytest) and integration tests (rostest, simulated Crazyflies), up to $JOBS at a time =="
echo "load average at start: $(cut -d' ' -f1-3 /proc/loadavg)"
t0=$(date +%s)
held_passes=0; most_running=0
sample_cpu
while [ "${#queue[@]}" -gt 0 ] || [ "${#running[@]}" -gt 0 ]; do
  while [ "${#running[@]}" -lt "$JOBS" ] && [ "${#queue[@]}" -gt 0 ]; do
    pick="$(pick_job)"
    if [ "$pick" -lt 0 ]; then held_passes=$((held_passes + 1)); break; fi
    start_job "${queue[$pick]}"; queue=("${queue[@]:0:$pick}" "${queue[@]:$((pick + 1))}")
    cpu_samples=("${cpu_samples[@]: -1}")     # what the new job's start costs shows before the next one
  done
  [ "${#running[@]}" -le "$most_running" ] || most_running="${#running[@]}"
  sleep 0.5
  sample_cpu
  still=()
  for id in "${running[@]}"; do
    if [ -f "$RESULTS/jobs/$(key_of "$id").rc" ]; then finish_job "$id"; else still+=("$id"); fi
  done
  running=("${still[@]:-}"); [ -n "${running[0]:-}" ] || running=()
done
set +m

read -r py_pass py_fail <<<"$(/usr/bin/python3 - "$RESULTS/pytest.xml" <<'PY'
import sys, xml.etree.ElementTree as ET
try:
    r = ET.parse(sys.argv[1]).getroot()
    s = r if r.tag == "testsuite" else r.find("testsuite")
    t, f, e, k = (int(s.get(x, 0)) for x in ("tests", "failures", "errors", "skipped"))
    print(t - f - e - k, f + e)
except Exception:
    print(0, 1)
PY
)"
if [ "$pytest_rc" -ne 0 ] && [ "$py_fail" -eq 0 ]; then py_fail=1; fi

echo "== summary =="
echo "tests took $(( $(date +%s) - t0 )) s (up to $most_running at a time; starts held back $((held_passes / 2)) s" \
     "for want of $IDLE_CORES idle cores); load average at the end: $(cut -d' ' -f1-3 /proc/loadavg)"
echo "lint: $( [ "$lint_fail" -eq 0 ] && echo clean || echo FAILED ); types: $( [ "$types_fail" -eq 0 ] && echo clean || echo FAILED ); pytest: $py_pass passed, $py_fail failed;" \
     "rostest: $ros_pass passed, $ros_fail failed${failed:+ (failed:$failed)}"
for id in $failed; do echo "why $id: $(reason_of "$(log_of "$id")")"; done
echo "$((lint_pass + types_pass + py_pass + ros_pass)) passed, $((lint_fail + types_fail + py_fail + ros_fail)) failed"
[ $((lint_fail + types_fail + py_fail + ros_fail)) -eq 0 ]
