#!/usr/bin/env bash
# Runs every test of the stack on a fresh machine: installs what is missing, builds the
# workspace, then runs the linter, the pytest unit tests and every rostest launch file
# (simulated Crazyflies, no hardware). Ends with one summary line "N passed, N failed"
# (the lint counts as one check).
set -uo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$REPO/tools/bootstrap.sh" --with-cflib || { echo "0 passed, 1 failed"; exit 1; }
source "$REPO/tools/env.sh"
cd "$REPO"

RESULTS="$REPO/.ws/test_results"
rm -rf "$RESULTS"; mkdir -p "$RESULTS"
export ROS_LOG_DIR="$RESULTS/ros_log"
export CRAZYFLIE_TOC_CACHE="$RESULTS/toc_cache"

echo "== lint (ruff, settings in ruff.toml) =="
if "$REPO/.ws/venv/bin/ruff" check --no-cache "$REPO"; then lint_pass=1; lint_fail=0; else lint_pass=0; lint_fail=1; fi

echo "== unit tests (pytest) =="
/usr/bin/python3 -m pytest -q -rs --junitxml="$RESULTS/pytest.xml" "$@"
pytest_rc=$?
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

echo "== integration tests (rostest, simulated Crazyflies) =="
ros_pass=0; ros_fail=0; failed=""
for t in $(ls crazyflie_*/test/rostest/*.test 2>/dev/null | sort); do
  pkg="${t%%/*}"; name="$(basename "$t")"
  start=$(date +%s)
  if timeout 600 rostest "$pkg" "$name" > "$RESULTS/rostest_${pkg}_${name}.log" 2>&1; then
    ros_pass=$((ros_pass + 1)); echo "PASS $pkg/$name ($(( $(date +%s) - start )) s)"
  else
    ros_fail=$((ros_fail + 1)); failed="$failed $pkg/$name"
    echo "FAIL $pkg/$name ($(( $(date +%s) - start )) s)"
    tail -n 40 "$RESULTS/rostest_${pkg}_${name}.log" | sed 's/^/    /'
  fi
done

echo "== summary =="
echo "lint: $( [ "$lint_fail" -eq 0 ] && echo clean || echo FAILED ); pytest: $py_pass passed, $py_fail failed;" \
     "rostest: $ros_pass passed, $ros_fail failed${failed:+ (failed:$failed)}"
echo "$((lint_pass + py_pass + ros_pass)) passed, $((lint_fail + py_fail + ros_fail)) failed"
[ $((lint_fail + py_fail + ros_fail)) -eq 0 ]
