#!/usr/bin/env python3
"""The swarm demo's flight for 1, 9 and 49 simulated Crazyflies: figure-8 tracking error per Crazyflie, CPU.

Each case runs ``roslaunch crazyflie_demo swarm.launch sim:=true monitor:=true n:=N`` (the demo:
takeoff by broadcast, the computed figure-8 at 0.76 m/s mean / 1.48 m/s top started by one
broadcast, a formation change by go_to, land) and reads the monitor's figures: the distance of
each Crazyflie's true position (the world's) to its plan over the figure-8 and its settling second,
its mean per Crazyflie; the swarm's mean of those, the worst Crazyflie's, and the largest single
error. CPU: the server's and the world's processes (/proc, user + system) from every Crazyflie
connected to the end of the flight, as a share of one core.

mocap Hz: the motion-capture rate the server's radio budget chose for each radio (its log), i.e. the
poses per second each Crazyflie on that radio gets; ``--dongle-model`` plugs in another Crazyradio model.

Usage (takes the ROS lock on a shared machine; about a minute per case):
    source tools/env.sh
    flock /tmp/ros.lock bench/bench_swarm_flight.py [--counts 1,9,49] [--dongle-model PA|PA-99.55|2.0]
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import time
from typing import Dict, Optional

import bench_support as bs


def node_pids(master, names) -> Dict[str, int]:
    import xmlrpc.client
    out = {}
    for n in names:
        try:
            out[n] = int(xmlrpc.client.ServerProxy(master.lookupNode(n)).getPid("/bench")[2])
        except Exception:
            pass
    return out


MOCAP_PLAN = re.compile(r"motion capture on radio (\d+) at (\d+) Hz")


def mocap_rates(log_path: str) -> str:
    """The motion-capture rate per radio the server logged (Hz, in radio order), e.g. "50/55/55"."""
    try:
        with open(log_path, errors="replace") as f:
            found = dict(MOCAP_PLAN.findall(f.read()))
    except OSError:
        return "?"
    return "/".join(found[k] for k in sorted(found, key=int)) or "?"


def run_case(n: int, timeout: float, dongle_model: str = "PA") -> dict:
    import rosgraph
    work = tempfile.mkdtemp(prefix="cf_swarm_flight_")
    stats = os.path.join(work, "stats.json")
    port = bs.free_port()
    env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:%d" % port, ROS_LOG_DIR=os.path.join(work, "log"),
               CRAZYFLIE_TOC_CACHE=os.path.join(work, "toc"))
    log = open(os.path.join(work, "launch.log"), "w")
    proc = subprocess.Popen(["roslaunch", "-p", str(port), "crazyflie_demo", "swarm.launch", "sim:=true",
                             "monitor:=true", "n:=%d" % n, "stats_file:=" + stats,
                             "plot:=" + os.path.join(work, "swarm.png"),
                             "sim_address:=127.0.0.1:%d" % bs.free_port(), "vrpn_port:=%d" % bs.free_port(),
                             "dongle_model:=" + dongle_model],
                            stdout=log, stderr=subprocess.STDOUT, env=env)
    result: dict = {"work": work}
    start: Optional[Dict[str, float]] = None
    last: Dict[str, float] = {}
    t_start = t_last = 0.0
    t0 = time.monotonic()
    try:
        os.environ["ROS_MASTER_URI"] = env["ROS_MASTER_URI"]
        master = rosgraph.Master("/bench")
        want = {"/cf%d/emergency" % (i + 1) for i in range(n)} | {"/takeoff"}
        pids: Dict[str, int] = {}
        while proc.poll() is None and time.monotonic() - t0 < timeout:
            try:
                if start is None:
                    _, _, srvs = master.getSystemState()
                    if want <= {s for s, _ in srvs}:
                        pids = node_pids(master, ("/crazyflie_server", "/crazyflie_sim"))
                        start = {k: bs.process_cpu_seconds(p) for k, p in pids.items()}
                        t_start = time.monotonic()
                        result["connect_s"] = t_start - t0
                else:
                    last = {k: bs.process_cpu_seconds(p) for k, p in pids.items()}
                    t_last = time.monotonic()
            except Exception:
                pass                      # master not up yet, or a process just ended
            time.sleep(0.25)
        if proc.poll() is None:
            result["error"] = "no end within %.0f s" % timeout
    finally:
        if proc.poll() is None:
            proc.terminate()
            proc.wait(30)
        log.close()
    if os.path.exists(stats):
        with open(stats) as f:
            result.update(json.load(f))
    logs = [os.path.join(root, name) for root, _, files in os.walk(work) for name in files
            if name.endswith(".log") and "crazyflie_server" in name] + [os.path.join(work, "launch.log")]
    result["mocap_hz"] = next((r for r in map(mocap_rates, logs) if r != "?"), "?")
    if start and last and t_last > t_start:
        result["cpu"] = {k: (last[k] - start[k]) / (t_last - t_start) for k in start if k in last}
    return result


def main() -> int:
    ap = bs.parser(__doc__, "swarm_flight.txt", 0.0, counts="1,9,49")
    ap.add_argument("--dongle-model", default="PA", help="the simulated Crazyradio model (PA, PA-99.55, 2.0)")
    args = ap.parse_args()
    table = bs.Table(
        ["swarm demo flight (swarm.launch sim:=true): figure-8 2 x 1 m, 8 s, 0.76 m/s mean, 1.48 m/s top,",
         "started by one broadcast relative to each start; Mellinger controller, Kalman estimator fed by the",
         "server's packed broadcasts of the world's VRPN motion capture (100 Hz, 0.5 mm noise, 5 ms latency)",
         "Crazyradio model: %s" % args.dongle_model, bs.machine_line(), ""],
        [("CFs", "4d"), ("fig-8 mean cm", "14.2f"), ("worst CF cm", "14.2f"), ("max cm", "12.2f"),
         ("server CPU", "10.0%"), ("world CPU", "11.0%"), ("connect s", "10.1f"), ("mocap Hz", "12"),
         ("result", "8")])
    for n in bs.counts_of(args.counts):
        r = run_case(n, timeout=300.0, dongle_model=args.dongle_model)
        fig = (r.get("phases") or {}).get("figure8")
        cpu = r.get("cpu", {})
        if fig is None:
            table.add("%4d   failed: %s (logs in %s)" % (n, r.get("error") or r.get("result"), r["work"]))
        else:
            table.row(n, 100 * fig["mean"], 100 * fig["worst_mean"], 100 * fig["max"],
                      cpu.get("/crazyflie_server", float("nan")), cpu.get("/crazyflie_sim", float("nan")),
                      r.get("connect_s", float("nan")), r.get("mocap_hz", "?"), r.get("result"))
    table.write(args.out, [
        "fig-8 mean: the swarm's mean of each Crazyflie's mean error (true position - plan) over the",
        "figure-8 and its settling second; worst CF: the largest of those means; max: the largest single error.",
        "CPU: share of one core from every Crazyflie connected to the end of the flight (user + system).",
        "mocap Hz: the rate the radio budget chose per radio (the poses per second of each Crazyflie on it)."])
    return 0


if __name__ == "__main__":
    sys.exit(main())
