#!/usr/bin/env python3
"""The fault table in swarm mode: four Crazyflies of crazyflie_demo/config/swarm4.yaml hovering on their
onboard high-level commanders (the server's packed motion-capture broadcasts, its emergency-stop watchdog
keep-alive on, as swarm mode's defaults are), one fault per row, judged on every Crazyflie's truth.

Usage (takes the ROS lock on a shared machine; about 4 minutes):
    source tools/env.sh
    flock /tmp/ros.lock bench/bench_faults_swarm.py              # -> bench/results/faults_swarm.txt
    flock /tmp/ros.lock bench/bench_faults_swarm.py --rows swarm_hide --out -
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from typing import Any, Dict, List, Tuple

try:
    import crazyflie_driver.srv  # noqa: F401  (the catkin workspace: source tools/env.sh first)
except ImportError:
    sys.exit("bench_faults_swarm: the catkin workspace is not on the path: source tools/env.sh first")

from fault_table import harness  # noqa: E402
from fault_table.harness import HOVER_SPEED_MS, HOVER_TOLERANCE_M, SAMPLE_HZ  # noqa: E402
from fault_table.swarm import SWARM_FILE, SwarmBench, SwarmRow, rows  # noqa: E402

import bench_support as bs  # noqa: E402


def lines(row: SwarmRow, r: Dict[str, Any]) -> List[str]:
    if "error" in r:
        return ["%s: bench error: %s" % (row.title, r["error"]), ""]
    out = ["%s (addressed: %s)" % (row.title, ", ".join(row.affected)), "  does:     %s" % r["does"],
           "  safe:     %s" % (r["safe"] or "not within the %.0f s observed: %s"
                                % (row.observe_s, ", ".join(r["unsafe"])))]
    for i, where in enumerate(r["reported"] or ["nowhere"]):
        out.append("  %s %s" % ("reported:" if i == 0 else "         ", where))
    out += ["  (bench: %.1f s to a hover before the fault)" % r["setup_s"], ""]
    return out


def markdown(results: List[Tuple[SwarmRow, Dict[str, Any]]]) -> List[str]:
    out = ["| fault (swarm mode, 4 Crazyflies) | what the Crazyflies do | all safe after |", "|---|---|---|"]
    for row, r in results:
        if "error" in r:
            out.append("| %s | bench error: %s | |" % (row.title, r["error"]))
            continue
        safe = "—: %s still flying" % ", ".join(r["unsafe"]) if r["safe_s"] is None else "%.2f s" % r["safe_s"]
        out.append("| %s | %s | %s |" % (row.title, r["does"], safe))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", help="comma-separated row keys (default: all): " + ",".join(r.key for r in rows()))
    ap.add_argument("--out", default=os.path.join(bs.RESULTS, "faults_swarm.txt"), help="'-' for stdout only")
    args = ap.parse_args()
    chosen = harness.chosen(rows(), args.rows, "bench_faults_swarm")
    if chosen is None:
        return 1
    commit = harness.commit_line()
    t_start = time.monotonic()
    results = harness.run_rows(SwarmBench, chosen, "cf_faults_swarm_", "bench_faults_swarm",
                               lambda row: "%s ..." % row.title, lines)
    head = ["fault table, swarm mode: %s (4 Crazyflies, cf1 and cf2 on one radio, cf3 and cf4 on one each), "
            "hovering at 0.5 m over their initial positions on the onboard high-level commander; the server's "
            "packed motion-capture broadcasts from the world's VRPN at 100 Hz; its emergency-stop watchdog "
            "keep-alive on (swarm mode's default); world at fixed speed 1" % os.path.relpath(SWARM_FILE, bs.REPO),
            "safe = on the floor with the motors off, or within %.2f m of its point and slower than %.1f m/s until "
            "the row ends; times from the fault; truth sampled at %.0f Hz" % (HOVER_TOLERANCE_M, HOVER_SPEED_MS,
                                                                             SAMPLE_HZ),
            "command: flock /tmp/ros.lock bench/bench_faults_swarm.py   (%.0f s for %d rows)"
            % (time.monotonic() - t_start, len(results)),
            "stack at: %s" % commit,
            "machine: %s, %s, Python %s, %d CPUs, load average %s" % (
                platform.machine(), platform.platform(terse=True), platform.python_version(), os.cpu_count() or 0,
                " ".join("%.2f" % x for x in os.getloadavg())), ""]
    text = "\n".join(head + [x for row, r in results for x in lines(row, r)] + ["", "README table:", ""]
                     + markdown(results)) + "\n"
    if args.out == "-":
        print("\n".join(markdown(results)))
    else:
        with open(args.out, "w") as f:
            f.write(text)
        print("written to %s" % args.out)
    return 0 if all("error" not in r for _, r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
