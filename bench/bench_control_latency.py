#!/usr/bin/env python3
"""The chapter's control path end to end: motion-capture stamp -> radio packet carrying the setpoint.

Six simulated Crazyflies hover on two fake Crazyradios (4 + 2) under the chapter's host-side
position controller, in the full ROS stack: the simulated world publishes Vicon-style tf (stamped
with the capture time), one ``controller`` node per Crazyflie looks the pose up and publishes
``cmd_vel``, ``crazyflie_server`` sends it over the fake dongle. For every command the bench asks:
how long after the stamp of the pose it was computed from did the radio packet carrying it reach
the (fake) dongle's air, and was it sent at all (a newer command may replace it before the
dongle gets to it)?

How it knows: the controller repeats each command on ``~cmd_vel_stamped`` stamped with its pose;
this process runs the simulated world (the unmodified ``crazyflie_sim`` node, in-process) with a
tap on its air that notes each RPYT packet's arrival time and bytes. A command is "sent" when a
packet with exactly its bytes reaches the air after its pose's stamp. Stamps and the tap use the
same clock (ROS time = wall time, no sim time).

Usage (takes the ROS lock on a shared machine; ~1 min per case):
    source tools/env.sh
    flock /tmp/ros.lock bench/bench_control_latency.py [--seconds 15] [--compute-on-pose] [--logging]
    flock /tmp/ros.lock bench/bench_control_latency.py --all      # the cases of bench/results/control_latency.txt
"""
from __future__ import annotations

import argparse
import statistics
import sys
import threading
import time
from typing import Dict, List, Optional, Tuple

import bench_support as bs

SIM_ADDRESS = "127.0.0.1:19899"
TARGET_Z = 0.5
VEHICLES = [  # name, uri, x, y: four on dongle 0, two on dongle 1
    ("crazyflie%d" % (i + 1), "radio://%d/%d/2M/E7E7E7E7%02X" % (d, 80 if d == 0 else 90, i + 1),
     0.6 * (i % 3), 0.6 * (i // 3))
    for i, d in enumerate((0, 0, 0, 0, 1, 1))
]


def launch_text(compute_on_pose: bool, logging_on: bool) -> str:
    rows = ["<launch>",
            '  <include file="$(find crazyflie_driver)/launch/crazyflie_server.launch">',
            '    <arg name="sim" value="true" /><arg name="sim_address" value="%s" />' % SIM_ADDRESS,
            "  </include>",
            '  <group ns="crazyflie_sim">',
            '    <param name="address" value="%s" />' % SIM_ADDRESS,
            '    <param name="mocap" value="vicon" /><param name="mocap_rate" value="100.0" />',
            '    <param name="mocap_noise" value="0.0005" /><param name="dongles" value="2" />',
            '    <param name="seed" value="1" />',
            '    <param name="vehicles" type="str" value="[%s]" />' % ", ".join(
                "{uri: '%s', name: %s, x: %s, y: %s}" % (u, n, x, y) for n, u, x, y in VEHICLES),
            "  </group>"]
    for name, uri, x, y in VEHICLES:
        rows += ['  <group ns="%s">' % name,
                 '    <include file="$(find crazyflie_driver)/launch/crazyflie_add.launch">',
                 '      <arg name="uri" value="%s" /><arg name="tf_prefix" value="%s" />' % (uri, name),
                 '      <arg name="enable_logging" value="%s" />' % logging_on,
                 "    </include>",
                 '    <include file="$(find crazyflie_controller)/launch/crazyflie2.launch">',
                 '      <arg name="frame" value="/vicon/%s/%s" />' % (name, name),
                 "    </include>",
                 '    <param name="controller/computeOnPose" value="%s" />' % ("true" if compute_on_pose else "false"),
                 '    <node name="pose" pkg="crazyflie_demo" type="publish_pose.py">',
                 '      <param name="name" value="goal" /><param name="rate" value="30" />',
                 '      <param name="x" value="%s" /><param name="y" value="%s" /><param name="z" value="%s" />'
                 % (x, y, TARGET_Z),
                 "    </node>",
                 "  </group>"]
    rows.append("</launch>")
    return "\n".join(rows) + "\n"


class AirTap:
    """Arrival time (wall) and bytes of every RPYT setpoint packet on the simulated air, per address."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.packets: Dict[bytes, List[Tuple[float, bytes]]] = {}

    def install(self) -> None:
        from crazyflie_driver.crtp.packet import PORT_COMMANDER
        from crazyflie_driver.sim.air import medium

        original = medium.LocalMedium.transmit
        tap = self

        def transmit(self_, dongle, channel, datarate, address, data, ack_enabled=True, arc=3):
            if len(data) == 15 and (data[0] >> 4) == PORT_COMMANDER and (data[0] & 0x03) == 0:
                t = time.time()
                with tap.lock:
                    tap.packets.setdefault(bytes(address), []).append((t, bytes(data[1:])))
            return original(self_, dongle, channel, datarate, address, data, ack_enabled, arc)

        medium.LocalMedium.transmit = transmit


def address_of(uri: str) -> bytes:
    from crazyflie_driver.crtp.uri import parse_uri
    return bytes(parse_uri(uri).address)


def measure(tap: AirTap, seconds: float, settle_s: float, result: dict) -> None:
    """The bench's thread inside the sim node's process: take off, settle, record, pair (an exception
    and the end of the case are handled by ``bench_support.ros_graph_with_sim_node``)."""
    import rospy
    from geometry_msgs.msg import TwistStamped
    from std_srvs.srv import Empty

    from crazyflie_driver.protocol.commander import rpyt_packet
    from crazyflie_driver.server.setpoint import setpoint_from_twist
    from crazyflie_driver.sim.air.medium import RemoteMedium

    bs.wait_for_ros()
    names = [v[0] for v in VEHICLES]
    commands: Dict[str, List[Tuple[float, float, bytes]]] = {n: [] for n in names}
    lock = threading.Lock()

    def on_cmd(name):
        def cb(msg: TwistStamped) -> None:
            t = msg.twist
            sp = setpoint_from_twist(t.linear.x, t.linear.y, t.linear.z, t.angular.z)
            payload = rpyt_packet(sp.roll, sp.pitch, sp.yawrate, sp.thrust).data
            with lock:
                commands[name].append((time.time(), msg.header.stamp.to_sec(), bytes(payload)))
        return cb
    for n in names:
        rospy.Subscriber("/%s/controller/cmd_vel_stamped" % n, TwistStamped, on_cmd(n), queue_size=1000)
    for n in names:
        rospy.wait_for_service("/%s/takeoff" % n, 120.0)
    for n in names:
        rospy.ServiceProxy("/%s/takeoff" % n, Empty)()
    host, _, port = SIM_ADDRESS.rpartition(":")
    world = RemoteMedium(host, int(port))
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline:
        zs = [world.control("vehicle_state", uri=n)["position"][2] for n in names]
        if all(abs(z - TARGET_Z) < 0.05 for z in zs):
            break
        time.sleep(0.2)
    else:
        result["error"] = "not all hovering after 60 s: z = %s" % zs
        return
    time.sleep(settle_s)
    t0 = time.time()
    time.sleep(seconds)
    t1 = time.time()
    time.sleep(0.5)              # packets of the last commands
    with lock:
        cmds = {n: [c for c in v if t0 <= c[1] < t1] for n, v in commands.items()}
    with tap.lock:
        packets = {a: list(v) for a, v in tap.packets.items()}
    result.update(pair(cmds, packets, {n: address_of(u) for n, u, _, _ in VEHICLES}))
    result["positions"] = [world.control("vehicle_state", uri=n)["position"] for n in names]


def pair(cmds: Dict[str, List[Tuple[float, float, bytes]]], packets: Dict[bytes, List[Tuple[float, bytes]]],
         addresses: Dict[str, bytes]) -> dict:
    """Latencies (stamp -> first packet with the command's bytes) and the commands never sent."""
    latencies: List[float] = []
    per_vehicle: Dict[str, Tuple[int, int]] = {}
    for name, rows in cmds.items():
        on_air = packets.get(addresses[name], [])
        by_bytes: Dict[bytes, List[float]] = {}
        for t, payload in on_air:
            by_bytes.setdefault(payload, []).append(t)
        sent = 0
        for _, stamp, payload in rows:
            times = [t for t in by_bytes.get(payload, ()) if t >= stamp]
            if times:
                latencies.append(times[0] - stamp)
                sent += 1
        per_vehicle[name] = (len(rows), sent)
    total = sum(n for n, _ in per_vehicle.values())
    sent = sum(s for _, s in per_vehicle.values())
    return {"latencies": latencies, "commands": total, "never_sent": total - sent, "per_vehicle": per_vehicle}


def run_case(compute_on_pose: bool, logging_on: bool, seconds: float, settle_s: float) -> dict:
    """Runs one case in a child process (one ROS graph each) and returns its figures."""
    return bs.run_child(__file__, ["--seconds", str(seconds), "--settle", str(settle_s)]
                        + (["--compute-on-pose"] if compute_on_pose else []) + (["--logging"] if logging_on else []),
                        timeout=seconds + settle_s + 240)


def child(out: str, compute_on_pose: bool, logging_on: bool, seconds: float, settle_s: float) -> None:
    """One ROS graph: roslaunch (master, server, adds, controllers, goals) + the sim node in here."""
    tap = AirTap()
    tap.install()
    bs.ros_graph_with_sim_node(launch_text(compute_on_pose, logging_on),
                               lambda result, _roslaunch: measure(tap, seconds, settle_s, result), out,
                               prefix="cf_latency_")


def summary(r: dict) -> Optional[Tuple[float, float, float, int]]:
    lat = r.get("latencies") or []
    if not lat:
        return None
    return (1000 * statistics.median(lat), 1000 * bs.percentile(lat, 99),
            100.0 * r["never_sent"] / max(1, r["commands"]), r["commands"])


def main() -> int:
    ap = bs.parser(__doc__, "control_latency.txt", 15.0)
    ap.add_argument("--settle", type=float, default=3.0)
    ap.add_argument("--compute-on-pose", action="store_true", help="controllers compute on each pose")
    ap.add_argument("--logging", action="store_true", help="the fixed log blocks on (the chapter: off)")
    ap.add_argument("--all", action="store_true", help="timer / on-pose x logging off / on, into --out")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child, args.compute_on_pose, args.logging, args.seconds, args.settle)
        return 0
    cases = [(False, False), (True, False), (False, True), (True, True)] if args.all else \
        [(args.compute_on_pose, args.logging)]
    lines = ["control path: mocap stamp -> tf -> controller -> cmd_vel -> crazyflie_server -> packet on the "
             "fake Crazyradio; 6 Crazyflies hovering, 4 + 2 on two dongles, Vicon-style tf at 100 Hz, "
             "%.0f s measured per case" % args.seconds,
             bs.machine_line(),
             "",
             "%-22s %8s %10s %12s %9s %12s" % ("controller", "logging", "commands", "median ms", "p99 ms",
                                               "never sent %")]
    print("\n".join(lines), flush=True)
    for on_pose, logging_on in cases:
        r = run_case(on_pose, logging_on, args.seconds, args.settle)
        mode = "on each pose" if on_pose else "50 Hz timer (chapter)"
        s = summary(r)
        if s is None:
            line = "%-22s %8s   failed: %s" % (mode, "on" if logging_on else "off", r.get("error", "no result"))
        else:
            line = "%-22s %8s %10d %12.1f %9.1f %12.1f" % (mode, "on" if logging_on else "off", s[3], s[0], s[1],
                                                          s[2])
        print(line, flush=True)
        lines.append(line)
    if args.all:
        bs.write_lines(args.out, lines)
    return 0


if __name__ == "__main__":
    sys.exit(main())
