#!/usr/bin/env python3
"""VRPN client throughput and receive-to-publish latency, for 1, 10 and 50 trackers at 100 Hz.

1. Capacity: a recorded 100 Hz stream (every tick's messages in one read, as the server sends
   them) is fed through the node's path without a ROS master: VrpnSession (framing, ids,
   decoding) -> VrpnBridge (names, Y-up rotation, staleness) -> PoseStamped and the tf
   TransformStamped filled and serialised (what rospy.publish and tf2_ros do per pose). Prints
   the poses per second one core sustains and the CPU share needed at the real rate.
2. Latency: the fake VRPN server streams over loopback for a few seconds; per pose, the time from
   the socket read returning to the messages being serialised (median, p99), and from the
   server's header timestamp to the same point (adds the server and the kernel).

Run: /usr/bin/python3 bench/bench_vrpn.py  (writes bench/results/vrpn.txt)
"""
from __future__ import annotations

import io
import os
import platform
import statistics
import sys
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))

import bench_support  # noqa: E402,F401  (the sources and the tests' support on the path)
from crazyflie_driver.mocap.vrpn_bridge import VrpnBridge, config_from_params  # noqa: E402
from crazyflie_driver.mocap.vrpn_client import VrpnClient, VrpnSession  # noqa: E402
from crazyflie_driver.mocap.vrpn_server import VrpnTestServer, circle_pose  # noqa: E402

try:
    from geometry_msgs.msg import PoseStamped, TransformStamped
    from tf2_msgs.msg import TFMessage
    HAVE_MSGS = True
except ImportError:                     # no ROS messages: measure the ROS-free part only
    HAVE_MSGS = False

FLEETS = (1, 10, 50)
RATE = 100.0
LATENCY_SECONDS = 3.0


def make_publisher():
    """What the node does with one PoseOut, minus the socket write of rospy."""
    if not HAVE_MSGS:
        return lambda out: None
    buf = io.BytesIO()

    def publish(out) -> None:
        msg = PoseStamped()
        msg.header.frame_id = "world"
        p, q = msg.pose.position, msg.pose.orientation
        p.x, p.y, p.z = out.position
        q.x, q.y, q.z, q.w = out.orientation
        t = TransformStamped()
        t.header.frame_id = "world"
        t.child_frame_id = out.child_frame
        tr, r = t.transform.translation, t.transform.rotation
        tr.x, tr.y, tr.z = out.position
        r.x, r.y, r.z, r.w = out.orientation
        buf.seek(0)
        msg.serialize(buf)
        buf.seek(0)
        TFMessage([t]).serialize(buf)

    return publish


def bridge_for(n: int) -> VrpnBridge:
    return VrpnBridge(config_from_params({"refresh_tracker_frequency": 1.0, "y_up": True, "broadcast_tf": True}))


def recorded_stream(n: int, seconds: float = 1.0):
    """(handshake bytes, [bytes of each 100 Hz tick]) as the fake server sends them."""
    names = ["Rigid Body %d" % i for i in range(n)]
    fns = {name: circle_pose(i) for i, name in enumerate(names)}
    server = VrpnTestServer(names, rate=RATE, pose_fn=lambda name, t: fns[name](name, t))
    head = server._descriptions()
    t0 = time.time()
    ticks = [server.frame(t0 + k / RATE)[0] for k in range(int(seconds * RATE))]
    return head, ticks


def capacity(n: int) -> float:
    head, ticks = recorded_stream(n)
    bridge = bridge_for(n)
    publish = make_publisher()
    count = [0]

    def on_pose(report):
        out = bridge.pose(report)
        if out is not None:
            publish(out)
            count[0] += 1

    session = VrpnSession(on_pose=on_pose)
    session.feed(head, 0.0)
    best = 0.0
    for _ in range(3):
        count[0] = 0
        t0 = time.perf_counter()
        reps = 0
        while time.perf_counter() - t0 < 1.0:
            for chunk in ticks:
                session.feed(chunk, time.monotonic())
            reps += 1
        dt = time.perf_counter() - t0
        best = max(best, count[0] / dt)
    assert count[0] == reps * len(ticks) * n, "poses lost in the capacity run"
    return best


def latency(n: int):
    names = ["cf%d" % i for i in range(n)]
    fns = {name: circle_pose(i) for i, name in enumerate(names)}
    bridge = bridge_for(n)
    publish = make_publisher()
    lock = threading.Lock()
    local, wire = [], []

    def on_pose(report):
        out = bridge.pose(report)
        if out is None:
            return
        publish(out)
        done_mono, done_wall = time.monotonic(), time.time()
        with lock:
            local.append(done_mono - report.receive_time)
            wire.append(done_wall - (report.server_sec + report.server_usec * 1e-6))

    with VrpnTestServer(names, rate=RATE, pose_fn=lambda name, t: fns[name](name, t), y_up=True) as server:
        client = VrpnClient("127.0.0.1", server.port, on_pose=on_pose, log=lambda level, text: None)
        client.start()
        if not client.wait_connected(5.0):
            raise RuntimeError("bench: the client did not connect to the fake server")
        time.sleep(0.5)
        with lock:
            local.clear()
            wire.clear()
        time.sleep(LATENCY_SECONDS)
        client.stop()
    with lock:
        got = len(local)
        local_s, wire_s = sorted(local), sorted(wire)

    def pct(xs, q):
        return xs[min(len(xs) - 1, int(q * len(xs)))] * 1e3

    return {"received_per_s": got / LATENCY_SECONDS, "expected_per_s": n * RATE,
            "local_median_ms": statistics.median(local_s) * 1e3, "local_p99_ms": pct(local_s, 0.99),
            "wire_median_ms": statistics.median(wire_s) * 1e3, "wire_p99_ms": pct(wire_s, 0.99)}


def main() -> int:
    lines = ["VRPN client: node path without ROS master (session -> bridge -> %s)"
             % ("PoseStamped + tf serialised" if HAVE_MSGS else "no ROS messages available"),
             "machine: %s, %s, Python %s, %d CPUs" % (platform.machine(), platform.processor() or "?",
                                                      platform.python_version(), os.cpu_count() or 0),
             "",
             "trackers  demand [poses/s]  capacity [poses/s]  CPU at demand  received [poses/s]"
             "  read->publish median / p99 [ms]  server stamp->publish median / p99 [ms]"]
    print("\n".join(lines), flush=True)
    for n in FLEETS:
        cap = capacity(n)
        lat = latency(n)
        row = ("%8d  %16.0f  %18.0f  %12.1f%%  %18.0f  %16.3f / %.3f  %22.3f / %.3f"
               % (n, n * RATE, cap, 100.0 * n * RATE / cap, lat["received_per_s"],
                  lat["local_median_ms"], lat["local_p99_ms"], lat["wire_median_ms"], lat["wire_p99_ms"]))
        print(row, flush=True)
        lines.append(row)
    os.makedirs(os.path.join(HERE, "results"), exist_ok=True)
    with open(os.path.join(HERE, "results", "vrpn.txt"), "w") as f:
        f.write("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
