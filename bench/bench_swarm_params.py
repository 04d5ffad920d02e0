#!/usr/bin/env python3
"""Swarm ``/update_params`` to every Crazyflie: how long it takes, how the radios share it, and whether it
holds up the estimators' placement at their first motion-capture pose.

One ROS graph per run, as bench_swarm.py builds it: crazyflie_server in swarm mode (n Crazyflies of the
demo's grid on three channels, one fake Crazyradio each, motion capture from the world's VRPN server) and
the unmodified simulated world node in this process, where the bench taps the simulated air. The
Crazyflies sit on the ground.

* early: ``/update_params`` of two parameters (``/allcfs/ring/effect``, ``/allcfs/ring/solidRed``) called
  the moment ``/takeoff`` is registered (every Crazyflie connected and configured), while the first fixes
  place the estimators;
* settled: the same call again once every estimator is placed (every ``first seen at`` line on rosout);
Parameter writes counted on the air: unicast writes by id (port 2 channel 2) and broadcast writes by name
(port 2 channel 3, SET_BY_NAME), each repeat counted.

* flying: with ``--load``, once more while every Crazyflie flies and a loop calls the swarm services as a
  busy user would (``/go_to`` by +-0.1 m every 0.5 s and a ``/start_trajectory`` of a trajectory never
  uploaded, refused, after each), the load that made the world fall behind real time.

For each call: its duration, and per radio the span (first to last) of the parameter-write packets on
the air (port 2, channel 2) and how many went out; the radios' spans overlap when the writes run in
parallel per radio. Placement: from ``/takeoff`` registered to the last Crazyflie placed.

Usage (takes the ROS lock on a shared machine):
    source tools/env.sh
    flock /tmp/ros.lock bench/bench_swarm_params.py [--counts 49] [--runs 2]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import threading
import time
from typing import Dict, List, Tuple

from bench_swarm import launch_text

import bench_support as bs

PORT_PARAM = 2
CHANNEL_WRITE = 2
CHANNEL_MISC = 3
SET_BY_NAME = 0
PARAMS = ("ring/effect", "ring/solidRed")


class Taps:
    """Parameter-write packets on the simulated air: (time, dongle)."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.writes: List[Tuple[float, int]] = []

    def install(self) -> None:
        from crazyflie_driver.sim.air import medium
        transmit = medium.LocalMedium.transmit
        taps = self

        def tapped(self_, dongle, channel, datarate, address, data, ack_enabled=True, arc=3):
            if len(data) > 1 and data[0] >> 4 == PORT_PARAM and (
                    (ack_enabled and data[0] & 0x03 == CHANNEL_WRITE)
                    or (not ack_enabled and data[0] & 0x03 == CHANNEL_MISC and data[1] == SET_BY_NAME)):
                with taps.lock:
                    taps.writes.append((time.monotonic(), dongle))
            return transmit(self_, dongle, channel, datarate, address, data, ack_enabled, arc)
        medium.LocalMedium.transmit = tapped

    def since(self, t0: float, t1: float) -> Dict[int, Tuple[float, float, int]]:
        """Per dongle: (first, last, count) of the writes in [t0, t1], times relative to t0."""
        out: Dict[int, Tuple[float, float, int]] = {}
        with self.lock:
            writes = [w for w in self.writes if t0 <= w[0] <= t1]
        for t, dongle in writes:
            first, last, n = out.get(dongle, (t - t0, t - t0, 0))
            out[dongle] = (min(first, t - t0), max(last, t - t0), n + 1)
        return out


def service_load(stop: threading.Event, counts: Dict[str, int]) -> None:
    """go_to back and forth and a refused start_trajectory, until ``stop``."""
    import rospy
    from geometry_msgs.msg import Point

    from crazyflie_driver.srv import GoTo, StartTrajectory
    go_to = rospy.ServiceProxy("/go_to", GoTo)
    start = rospy.ServiceProxy("/start_trajectory", StartTrajectory)
    sign = 1.0
    while not stop.is_set():
        go_to(0, True, Point(0.1 * sign, 0.0, 0.0), 0.0, rospy.Duration(0.5))
        counts["go_to"] = counts.get("go_to", 0) + 1
        sign = -sign
        try:
            start(0, 7, 1.0, False, True)
        except rospy.ServiceException:
            counts["refused"] = counts.get("refused", 0) + 1
        stop.wait(0.5)


def measure(taps: Taps, names: List[str], result: dict, load: bool) -> None:
    import rospy

    from crazyflie_driver.srv import UpdateParams
    bs.wait_for_ros()
    placed = record_placements()
    if not wait_for_service_registered("/takeoff", 300.0):
        result["error"] = "/takeoff not registered within 300 s"
        return
    ready = time.monotonic()
    for p in PARAMS:
        rospy.set_param("/allcfs/" + p, 3)
    call = rospy.ServiceProxy("/update_params", UpdateParams)
    calls = []
    stop, counts = threading.Event(), {}
    for label in ("early", "settled", "flying") if load else ("early", "settled"):
        prepare(label, placed, names, stop, counts)
        calls.append(timed_call(call, label, taps))
    stop.set()
    if load:
        from crazyflie_driver.srv import Land
        rospy.ServiceProxy("/land", Land)(0, 0.0, rospy.Duration(2.0))
        result["load"] = counts
    result["calls"] = calls
    result["placed"] = len(placed)
    result["placement_s"] = (max(placed.values()) - ready) if placed else float("nan")


def record_placements() -> Dict[str, float]:
    """Name -> when its estimator was placed (its ``first seen at`` line on rosout), filled as they come."""
    import rospy
    from rosgraph_msgs.msg import Log

    placed: Dict[str, float] = {}

    def on_log(msg: Log) -> None:
        if "first seen at" in msg.msg:
            name = msg.msg.split("swarm: ", 1)[-1].split(":", 1)[0]
            placed.setdefault(name, time.monotonic())
    rospy.Subscriber("/rosout_agg", Log, on_log, queue_size=1000)
    return placed


def wait_for_service_registered(service: str, timeout_s: float) -> bool:
    """Whether the master lists ``service`` within ``timeout_s``."""
    import rosgraph

    master = rosgraph.Master("/bench_swarm_params")
    deadline = time.monotonic() + timeout_s
    while service not in {s for s, _ in master.getSystemState()[2]}:
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


def prepare(label: str, placed: Dict[str, float], names: List[str], stop: threading.Event,
            counts: Dict[str, int]) -> None:
    """What comes before the call ``label``: nothing (early), every estimator placed (settled), or the
    swarm in the air under the service load (flying)."""
    import rospy

    if label == "settled":
        deadline = time.monotonic() + 300.0
        while len(placed) < len(names) and time.monotonic() < deadline:
            time.sleep(0.1)
    if label == "flying":
        from crazyflie_driver.srv import Takeoff
        rospy.ServiceProxy("/takeoff", Takeoff)(0, 0.5, rospy.Duration(2.0))
        time.sleep(3.0)
        threading.Thread(target=service_load, args=(stop, counts), daemon=True).start()
        time.sleep(5.0)


def timed_call(call, label: str, taps: Taps) -> dict:
    """One ``/update_params`` call: its duration, its error, and the parameter writes of each radio meanwhile."""
    t0 = time.monotonic()
    try:
        call(list(PARAMS))
        error = ""
    except Exception as e:
        error = str(e)[:300]
    t1 = time.monotonic()
    return {"label": label, "seconds": t1 - t0, "error": error,
            "radios": {str(k): v for k, v in sorted(taps.since(t0, t1).items())}}


def child(out: str, n: int, load: bool) -> None:
    import os

    from crazyflie_demo.swarm_grid import swarm_file_text
    from crazyflie_driver.server.swarm.config import load_swarm_file
    work = tempfile.mkdtemp(prefix="cf_swarm_params_")
    swarm_file = os.path.join(work, "swarm.yaml")
    with open(swarm_file, "w") as f:
        f.write(swarm_file_text(n))
    names = [cf.name for cf in load_swarm_file(swarm_file).crazyflies]
    taps = Taps()
    taps.install()
    text = launch_text(swarm_file, "127.0.0.1:%d" % bs.free_port(), bs.free_port())
    bs.ros_graph_with_sim_node(text, lambda result, _: measure(taps, names, result, load), out,
                               prefix="cf_swarm_params_")


def row(n: int, run: int, r: dict) -> List[str]:
    if "calls" not in r:
        return ["%4d %4d   failed: %s" % (n, run, r.get("error", "no result"))]
    lines = []
    for c in r["calls"]:
        spans = " ".join("r%s %.1f-%.1f s (%d)" % (k, v[0], v[1], v[2]) for k, v in sorted(c["radios"].items()))
        lines.append("%4d %4d %-8s %9.2f %12.1f   %s%s" % (
            n, run, c["label"], c["seconds"], r["placement_s"], spans, "  ERROR " + c["error"] if c["error"] else ""))
    if "load" in r:
        lines.append("%4d %4d load: %d go_to, %d refused start_trajectory" % (
            n, run, r["load"].get("go_to", 0), r["load"].get("refused", 0)))
    return lines


def main() -> int:
    ap = bs.parser(__doc__, "swarm_params.txt", 0.0, counts="49")
    ap.add_argument("--runs", type=int, default=2)
    ap.add_argument("--load", action="store_true", help="also call it while all fly under a service load")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--n", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child, args.n, args.load)
        return 0
    lines = ["swarm /update_params of %d parameters to every Crazyflie (on the ground, motion capture streaming)"
             % len(PARAMS), bs.machine_line(), "",
             "%4s %4s %-8s %9s %12s   %s" % ("CFs", "run", "call", "call s", "placement s",
                                              "per radio: parameter writes on the air, from the call (count)")]
    print("\n".join(lines), flush=True)
    for n in bs.counts_of(args.counts):
        for run in range(1, args.runs + 1):
            r = bs.run_child(__file__, ["--n", str(n)] + (["--load"] if args.load else []), timeout=900)
            for line in row(n, run, r):
                lines.append(line)
                print(line, flush=True)
    lines += ["",
              "early: called when /takeoff is registered, while the first fixes place the estimators; settled: "
              "once all are placed.",
              "placement s: /takeoff registered -> the last 'first seen at' (estimator placed) on rosout.",
              "flying (--load): all airborne at 0.5 m, /go_to +-0.1 m every 0.5 s and a refused /start_trajectory "
              "after each meanwhile."]
    bs.write_lines(args.out, lines)
    return 0


if __name__ == "__main__":
    sys.exit(main())
