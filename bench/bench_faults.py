#!/usr/bin/env python3
"""The fault table: each fault on a simulated flight through the real stack, and what the stack does.

One Crazyflie hovers at (0, 0, 0.5) in the full ROS stack: the simulated world (``crazyflie_sim_node``,
Vicon-style mocap at 100 Hz), ``crazyflie_server`` over the fake Crazyradio, and either the chapter's
host-side position controller (``controller`` + a ``goal`` publisher; path "chapter") or the onboard
high-level commander fed with the world's mocap as ``external_position`` (path "onboard"). Each row
injects one fault (through the world's fault operations, the ones ``rosrun crazyflie_tools fault``
uses, or by killing/calling a node) and measures, from the world's truth (position, velocity, motors,
sampled over the control channel at 50 Hz) and from the topics (/rosout_agg, /diagnostics,
/crazyflie1/status, the controller's ~state):

* what the stack does: how the vehicle moves after the fault (keeps hovering / descends / falls);
* time to a safe state: on the floor with the motors off, or hovering under control again
  (within 0.15 m of the goal and slower than 0.3 m/s until the end of the row), from the fault;
* where it is reported: the first warning/error lines of each node, the non-OK /diagnostics entries,
  the Crazyflie's status topic, the controller's state changes;
* anything lost: log packets counted lost by the server, a firmware lock that needs a reboot,
  a link that did not come back.

Nothing in here decides the reaction: the stack's nodes and their defaults do, so a re-run after a
change to the stack's reactions picks them up. A row runs on the graph the previous row left
hovering; a row that leaves the vehicle down (or a node dead) makes the next one start a fresh graph.

Usage (takes the ROS lock on a shared machine; about 5 minutes):
    source tools/env.sh
    flock /tmp/ros.lock bench/bench_faults.py --readme        # every row -> bench/results/faults.txt + README
    flock /tmp/ros.lock bench/bench_faults.py --rows loss30,emergency --out -
    flock /tmp/ros.lock bench/bench_faults.py --rows freeze,hide --readme   # measured again, merged by row key
"""
from __future__ import annotations

import argparse
import os
import sys
import time

try:
    import crazyflie_driver.srv  # noqa: F401  (the catkin workspace: source tools/env.sh first)
except ImportError:
    sys.exit("bench_faults: the catkin workspace is not on the path: source tools/env.sh first")

from fault_table import harness  # noqa: E402
from fault_table.harness import Bench  # noqa: E402
from fault_table.report import RUN_FIRST, table, write  # noqa: E402
from fault_table.rows import rows  # noqa: E402

import bench_support as bs  # noqa: E402  (after the workspace check: it names the fix)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", help="comma-separated row keys (default: all): " + ",".join(r.key for r in rows()))
    ap.add_argument("--out", default=os.path.join(bs.RESULTS, "faults.txt"), help="'-' for stdout only")
    ap.add_argument("--readme", action="store_true",
                    help="also put the short table into README.md (between its fault-table markers)")
    args = ap.parse_args()
    chosen = harness.chosen(rows(), args.rows, "bench_faults")
    if chosen is None:
        return 1
    commit = harness.commit_line()
    t_start = time.monotonic()
    order = sorted(chosen, key=lambda r: (r.path != "chapter", r.key not in RUN_FIRST,
                                          RUN_FIRST.index(r.key) if r.key in RUN_FIRST else 0))

    def write_so_far(results: harness.Results) -> None:
        if args.out != "-":                  # what is measured so far, should the run be cut short
            write(args, results, commit, time.monotonic() - t_start, partial=True)
    results = harness.run_rows(Bench, order, "cf_faults_", "bench_faults",
                               lambda row: "%s (%s path) ..." % (row.title, row.path),
                               lambda row, r: table([(row, r)]), write_so_far)
    write(args, results, commit, time.monotonic() - t_start, partial=False)
    return 0 if all("error" not in r for _, r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
