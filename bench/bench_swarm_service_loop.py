#!/usr/bin/env python3
"""49 flying Crazyflies under a busy user's service loop: do they all stay up, how long does a swarm
``/update_params`` take, and at what real-time factor does the world run meanwhile.

The graph is the swarm demo's (``roslaunch crazyflie_demo swarm.launch sim:=true demo:=false``: the
world node publishing /clock at ``speed`` (auto unless CRAZYFLIE_SIM_SPEED says otherwise), crazyflie_server
in swarm mode, VRPN motion capture). This process takes off every Crazyflie to 0.5 m, then for
``--seconds`` of wall time runs the loop: every 0.5 s a swarm ``/go_to`` by +-0.1 m (relative, 0.5 s) and
a ``/start_trajectory`` of a trajectory never uploaded (refused), every fourth round a ``/takeoff`` to
0.5 m (2 s); at a third and at two thirds of the loop ``/update_params`` of two ``/allcfs`` parameters.
Then land.

Measured on the world's truth (its control port: poses and world time, 5 Hz): the lowest Crazyflie
during the loop and how many were ever below 0.3 m; the real-time factor over the loop and its lowest
5 s window; each ``/update_params`` call in wall and world seconds; all landed at the end.

Usage (takes the ROS lock on a shared machine; about two minutes):
    source tools/env.sh
    flock /tmp/ros.lock bench/bench_swarm_service_loop.py [--n 49] [--seconds 60] [--busy 2]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import threading
import time
from typing import Dict, List, Tuple

import bench_support as bs

PARAMS = ("ring/effect", "ring/solidRed")
FLY_Z_M = 0.5
LOW_Z_M = 0.3
LANDED_Z_M = 0.05


class Truth:
    """World time and every Crazyflie's true height, polled from the world's control port."""

    def __init__(self, address: str) -> None:
        from crazyflie_driver.sim.air.medium import RemoteMedium, parse_address
        self.medium = RemoteMedium(*parse_address(address))
        self.lock = threading.Lock()
        self.samples: List[Tuple[float, float, Dict[str, float]]] = []     # wall, world, name -> z
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._poll, daemon=True)
        self._thread.start()

    def _poll(self) -> None:
        while not self._stop.is_set():
            try:
                p = self.medium.control("poses")
                with self.lock:
                    self.samples.append((time.monotonic(), float(p["time"]),
                                         {n: float(pos[2]) for n, pos in zip(p["names"], p["positions"])}))
            except Exception:
                pass
            self._stop.wait(0.2)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)

    def last(self) -> Dict[str, float]:
        with self.lock:
            return dict(self.samples[-1][2]) if self.samples else {}

    def world_now(self) -> float:
        return float(self.medium.control("time"))

    def between(self, t0: float, t1: float) -> List[Tuple[float, float, Dict[str, float]]]:
        with self.lock:
            return [s for s in self.samples if t0 <= s[0] <= t1]


def rtf(samples) -> Tuple[float, float]:
    """Real-time factor over the samples and its lowest 5 s (wall) window."""
    if len(samples) < 2:
        return float("nan"), float("nan")
    whole = (samples[-1][1] - samples[0][1]) / (samples[-1][0] - samples[0][0])
    low = whole
    j = 0
    for i in range(len(samples)):
        while j < len(samples) and samples[j][0] - samples[i][0] < 5.0:
            j += 1
        if j >= len(samples):
            break
        low = min(low, (samples[j][1] - samples[i][1]) / (samples[j][0] - samples[i][0]))
    return whole, low


def run(n: int, seconds: float, busy: int) -> List[str]:
    work = tempfile.mkdtemp(prefix="cf_service_loop_")
    port, sim_address = bs.free_port(), "127.0.0.1:%d" % bs.free_port()
    env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:%d" % port, ROS_LOG_DIR=os.path.join(work, "log"),
               CRAZYFLIE_TOC_CACHE=os.path.join(work, "toc"))
    os.environ["ROS_MASTER_URI"] = env["ROS_MASTER_URI"]
    hogs = [subprocess.Popen(["bash", "-c", "while :; do :; done"]) for _ in range(busy)]
    load = open("/proc/loadavg").read().split()[0]
    log = open(os.path.join(work, "launch.log"), "w")
    launch = subprocess.Popen(["roslaunch", "-p", str(port), "crazyflie_demo", "swarm.launch", "sim:=true",
                               "demo:=false", "n:=%d" % n, "sim_address:=" + sim_address,
                               "vrpn_port:=%d" % bs.free_port()], stdout=log, stderr=subprocess.STDOUT, env=env)
    lines: List[str] = []
    try:
        lines = fly(n, seconds, sim_address, work)
    finally:
        launch.terminate()
        try:
            launch.wait(60)
        except subprocess.TimeoutExpired:
            launch.kill()
        for h in hogs:
            h.kill()
        log.close()
    speed = os.environ.get("CRAZYFLIE_SIM_SPEED", "auto")
    head = "%d Crazyflies, speed %s, %d busy loops, load average %s before; logs in %s" % (n, speed, busy, load, work)
    return [head] + lines


def fly(n: int, seconds: float, sim_address: str, work: str) -> List[str]:  # noqa: C901  (one scripted run, read top to bottom)
    import rosgraph
    deadline = time.monotonic() + 60.0
    while not rosgraph.is_master_online() and time.monotonic() < deadline:
        time.sleep(0.2)
    import rospy
    from geometry_msgs.msg import Point

    from crazyflie_driver.srv import GoTo, Land, StartTrajectory, Takeoff, UpdateParams
    while not rospy.has_param("/use_sim_time") and time.monotonic() < deadline:
        time.sleep(0.2)
    rospy.init_node("bench_service_loop", disable_signals=True)
    from diagnostic_msgs.msg import DiagnosticArray
    world_status: List[Tuple[float, Dict[str, str]]] = []      # wall, the world's /diagnostics values

    def on_diagnostics(msg) -> None:
        for st in msg.status:
            if st.hardware_id == "crazyflie_sim":
                world_status.append((time.monotonic(), {kv.key: kv.value for kv in st.values}))
    rospy.Subscriber("/diagnostics", DiagnosticArray, on_diagnostics, queue_size=50)
    rospy.wait_for_service("/takeoff", timeout=300.0)
    for p in PARAMS:
        rospy.set_param("/allcfs/" + p, 3)
    takeoff = rospy.ServiceProxy("/takeoff", Takeoff)
    go_to = rospy.ServiceProxy("/go_to", GoTo)
    start = rospy.ServiceProxy("/start_trajectory", StartTrajectory)
    update = rospy.ServiceProxy("/update_params", UpdateParams)
    truth = Truth(sim_address)
    out: List[str] = []
    t_ready = time.monotonic()
    while True:                 # refused while the first fixes place the estimators
        try:
            takeoff(0, FLY_Z_M, rospy.Duration(2.0))
            break
        except rospy.ServiceException as e:
            if time.monotonic() - t_ready > 120.0:
                return out + ["takeoff refused for 120 s: %s" % e]
            time.sleep(1.0)
    out.append("takeoff accepted %.1f s (wall) after /takeoff was served" % (time.monotonic() - t_ready))
    t_up = time.monotonic()
    while time.monotonic() - t_up < 60.0:
        z = truth.last()
        if len(z) == n and min(z.values()) > 0.8 * FLY_Z_M:
            break
        time.sleep(0.2)
    z = truth.last()
    out.append("airborne: %d of %d above %.2f m, %.1f s (wall) after the takeoff" % (
        sum(1 for v in z.values() if v > 0.8 * FLY_Z_M), n, 0.8 * FLY_Z_M, time.monotonic() - t_up))
    counts = {"go_to": 0, "go_to failed": 0, "refused start_trajectory": 0, "takeoff": 0, "takeoff refused": 0}
    calls: List[str] = []

    def update_call(label: str) -> None:
        w0, s0 = time.monotonic(), truth.world_now()
        try:
            update(list(PARAMS))
            error = ""
        except Exception as e:
            error = "  ERROR " + str(e)[:200]
        calls.append("/update_params (%s): %.2f s wall, %.2f s world%s" % (
            label, time.monotonic() - w0, truth.world_now() - s0, error))
    t0 = time.monotonic()
    updaters = [threading.Timer(seconds * k / 3.0, update_call, args=("at %d s" % int(seconds * k / 3.0),))
                for k in (1, 2)]
    for u in updaters:
        u.daemon = True
        u.start()
    sign, rounds = 1.0, 0
    while time.monotonic() - t0 < seconds:
        r0 = time.monotonic()
        try:
            go_to(0, True, Point(0.1 * sign, 0.0, 0.0), 0.0, rospy.Duration(0.5))
            counts["go_to"] += 1
        except rospy.ServiceException:
            counts["go_to failed"] += 1
        sign = -sign
        try:
            start(0, 7, 1.0, False, True)
        except rospy.ServiceException:
            counts["refused start_trajectory"] += 1
        if rounds % 4 == 3:
            try:
                takeoff(0, FLY_Z_M, rospy.Duration(2.0))
                counts["takeoff"] += 1
            except rospy.ServiceException:
                counts["takeoff refused"] += 1
        rounds += 1
        time.sleep(max(0.0, 0.5 - (time.monotonic() - r0)))
    t1 = time.monotonic()
    for u in updaters:
        u.join(120.0)
    loop = truth.between(t0, t1)
    lowest = min((min(s[2].values()), s[1]) for s in loop if s[2]) if loop else (float("nan"), 0.0)
    low_names = sorted({k for s in loop for k, v in s[2].items() if v < LOW_Z_M})
    whole, worst = rtf(loop)
    out.append("loop: %.0f s wall, %.1f s world, %d rounds: %s" % (
        t1 - t0, loop[-1][1] - loop[0][1] if loop else float("nan"), rounds,
        ", ".join("%d %s" % (v, k) for k, v in counts.items())))
    out.append("real-time factor over the loop: %.2f; lowest 5 s window: %.2f" % (whole, worst))
    out.append("lowest Crazyflie during the loop: %.3f m (world t=%.1f s); below %.1f m at any sample: %d%s" % (
        lowest[0], lowest[1], LOW_Z_M, len(low_names), " (%s)" % ", ".join(low_names[:8]) if low_names else ""))
    seen = [v for t, v in world_status if t0 <= t <= t1]

    def span(key: str) -> str:
        vals = [float(v[key]) for v in seen if key in v]
        return "%.2f-%.2f" % (min(vals), max(vals)) if vals else "n/a"
    out.append("world's /diagnostics during the loop (%d): speed %s, real-time factor %s, host run-queue wait %s ms"
               % (len(seen), span("speed"), span("real-time factor"), span("host run-queue wait [ms]")))
    out += calls
    try:
        rospy.ServiceProxy("/land", Land)(0, 0.0, rospy.Duration(2.0))
    except rospy.ServiceException as e:
        out.append("land refused: %s" % e)
    t_land = time.monotonic()
    while time.monotonic() - t_land < 30.0:
        z = truth.last()
        if z and max(z.values()) < LANDED_Z_M:
            break
        time.sleep(0.2)
    z = truth.last()
    out.append("landed: %d of %d below %.2f m, %.1f s (wall) after /land" % (
        sum(1 for v in z.values() if v < LANDED_Z_M), n, LANDED_Z_M, time.monotonic() - t_land))
    truth.stop()
    rospy.signal_shutdown("bench done")
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=49)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--busy", type=int, default=0, help="shell busy loops alongside")
    ap.add_argument("--out", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "results",
                                                  "swarm_service_loop.txt"))
    args = ap.parse_args()
    lines = run(args.n, args.seconds, args.busy)
    lines.append(bs.machine_line())
    print("\n".join(lines), flush=True)
    with open(args.out, "a") as f:
        f.write("\n".join(lines) + "\n\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
