#!/usr/bin/env python3
"""Swarm mode on the wire: mocap-to-radio latency, radio load, connect time and CPU for 1, 16 and 49 Crazyflies.

Each case is one ROS graph: crazyflie_server in swarm mode (``~swarm_file``: n Crazyflies in the
demo's grid on up to three channels, one fake Crazyradio each; ``~mocap: vrpn``) and, in this
process, the unmodified simulated world node serving its motion capture as VRPN (100 Hz, 5 mm
noise so that consecutive poses differ on the wire, no modelled mocap latency: the figure is the
software's). The Crazyflies sit on the ground; the server streams their poses all the same.

* latency: for every pose the world's VRPN server sends (its stamp = the moment it is sent), the
  first packed broadcast on the simulated air (port 6) within 0.5 s that carries that Crazyflie's id
  with exactly those millimetres; median and p99 over the measured window, and the share of poses
  never sent (the server sends the newest pose when it falls behind, as it should).
* radio load: broadcast and unicast packets per second on each fake Crazyradio, and the radio's
  modelled busy share = (unicast packets × bulk round trip + broadcast packets × their air time +
  changes of address or ack mode × control transfer) / time, from the fake dongle's timing model
  (``DongleTiming``); on a Crazyradio 2.0 in inline mode no control transfer and a broadcast packet
  costs an inline round trip without ack wait.
* mocap Hz per Crazyflie: how often each Crazyflie's id went out in a packed broadcast, per second
  (the lowest and highest of the swarm).
* connect: from the world accepting connections to every Crazyflie's services and the swarm-wide
  ``/takeoff`` being registered (the server offers it once all are connected and configured),
  for each size, with an empty TOC cache and again with the cache the first run left (``--connect``).
* CPU: the server process (/proc, all threads) and this world process, per second of the window.

Usage (takes the ROS lock on a shared machine):
    source tools/env.sh
    flock /tmp/ros.lock bench/bench_swarm.py [--counts 1,16,49] [--seconds 10] [--connect] [--dongle-model 2.0]
"""
from __future__ import annotations

import argparse
import os
import statistics
import struct
import sys
import tempfile
import threading
import time
from typing import Dict, List, Tuple

import bench_support as bs

VRPN_NOISE_M = 0.005
#: A pose not on the air this long after it was sent counts as never sent: the server had sent a
#: newer one (a later broadcast with the same millimetres is a different, equal pose).
MAX_LATENCY_S = 0.5
SETTLE_S = 3.0


def launch_text(swarm_file: str, sim_address: str, vrpn_port: int, dongle_model: str = "PA") -> str:
    return "\n".join([
        "<launch>",
        '  <node pkg="crazyflie_driver" type="crazyflie_server" name="crazyflie_server" required="true">',
        '    <env name="CRAZYFLIE_BACKEND" value="sim" /><env name="CRAZYFLIE_SIM_ADDRESS" value="%s" />'
        % sim_address,
        '    <param name="swarm_file" value="%s" /><param name="mocap" value="vrpn" />' % swarm_file,
        '    <param name="vrpn_server" value="127.0.0.1:%d" />' % vrpn_port,
        "  </node>",
        '  <group ns="crazyflie_sim">',
        '    <param name="address" value="%s" /><param name="swarm_file" value="%s" />' % (sim_address, swarm_file),
        '    <param name="mocap" value="none" /><param name="vrpn" value="true" />',
        '    <param name="vrpn_port" value="%d" /><param name="mocap_noise" value="%s" />' % (vrpn_port, VRPN_NOISE_M),
        '    <param name="seed" value="1" /><param name="dongle_model" value="%s" />' % dongle_model,
        "  </group>",
        "</launch>", ""])


class Taps:
    """Poses the world's VRPN server sends (stamp, {name: mm}) and every packet on the simulated air."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.sent: List[Tuple[float, Dict[str, Tuple[int, int, int]]]] = []
        self.air: List[Tuple[float, int, bytes, bool, bytes]] = []    # time, dongle, address, ack, data
        self.world_listening = None

    def install(self) -> None:
        from crazyflie_driver.mocap.vrpn_server import VrpnTestServer
        from crazyflie_driver.sim.air import medium
        from crazyflie_driver.sim.world_server import WorldServer

        taps = self
        send_poses, transmit, start = VrpnTestServer.send_poses, medium.LocalMedium.transmit, WorldServer.start

        def tapped_send(self_, poses, t):
            n = send_poses(self_, poses, t)
            if n:
                # the server's packing: millimetres truncated toward zero (protocol.checks.milli_int16)
                mm = {name: tuple(int(float(v) * 1000.0) for v in pos) for name, pos, _ in poses}
                with taps.lock:
                    taps.sent.append((time.time(), mm))
            return n

        def tapped_transmit(self_, dongle, channel, datarate, address, data, ack_enabled=True, arc=3):
            with taps.lock:
                taps.air.append((time.time(), dongle, bytes(address), bool(ack_enabled), bytes(data)))
            return transmit(self_, dongle, channel, datarate, address, data, ack_enabled, arc)

        def tapped_start(self_):
            out = start(self_)
            taps.world_listening = time.monotonic()
            return out

        VrpnTestServer.send_poses = tapped_send
        medium.LocalMedium.transmit = tapped_transmit
        WorldServer.start = tapped_start


PORT_LOCALIZATION = 6
TYPE_EXTERNAL_POSE_PACKED = 9


def packed_items(data: bytes) -> List[Tuple[int, int, int, int]]:
    """(id, x mm, y mm, z mm) of a packed position or packed pose broadcast, else []."""
    if not data or (data[0] >> 4) != PORT_LOCALIZATION:
        return []
    channel = data[0] & 0x03
    if channel == 2:
        body, size = data[1:], 7
    elif channel == 1 and len(data) > 1 and data[1] == TYPE_EXTERNAL_POSE_PACKED:
        body, size = data[2:], 11
    else:
        return []
    return [struct.unpack_from("<B3h", body, k) for k in range(0, len(body) - size + 1, size)]


def pair(sent, air, ids: Dict[str, int], t0: float, t1: float) -> dict:
    """Each pose sent in [t0, t1) -> the first broadcast after it carrying exactly it."""
    first_seen: Dict[Tuple[int, int, int, int], List[float]] = {}
    for t, _, _, ack, data in air:
        if not ack:
            for item in packed_items(data):
                first_seen.setdefault(tuple(item), []).append(t)
    latencies, missing = [], 0
    for stamp, poses in sent:
        if not t0 <= stamp < t1:
            continue
        for name, mm in poses.items():
            times = first_seen.get((ids[name],) + mm, ())
            later = [t for t in times if stamp <= t <= stamp + MAX_LATENCY_S]
            if later:
                latencies.append(later[0] - stamp)
            else:
                missing += 1
    return {"latencies": latencies, "missing": missing}


def mocap_hz(air, t0: float, t1: float) -> List[float]:
    """Packed-broadcast items per second of each Crazyflie id (by dongle and id) in [t0, t1)."""
    count: Dict[Tuple[int, int], int] = {}
    for t, dongle, _, ack, data in air:
        if t0 <= t < t1 and not ack:
            for item in packed_items(data):
                count[(dongle, item[0])] = count.get((dongle, item[0]), 0) + 1
    return [c / (t1 - t0) for c in count.values()]


def radio_load(air, t0: float, t1: float, inline: bool = False) -> Dict[int, Dict[str, float]]:
    from crazyflie_driver.sim.air.dongle_timing import DongleTiming
    timing = DongleTiming()
    out: Dict[int, Dict[str, float]] = {}
    last: Dict[int, Tuple[bytes, bool]] = {}
    for t, dongle, address, ack, _ in air:
        if not t0 <= t < t1:
            last[dongle] = (address, ack)
            continue
        d = out.setdefault(dongle, {"broadcast": 0, "unicast": 0, "controls": 0})
        d["broadcast" if not ack else "unicast"] += 1
        prev = last.get(dongle)
        if prev is not None:
            d["controls"] += int(prev[0] != address) + int(prev[1] != ack)
        last[dongle] = (address, ack)
    span = t1 - t0
    for d in out.values():
        if inline:
            busy = d["unicast"] * timing.bulk_round_trip_s + d["broadcast"] * timing.inline_no_ack_s
        else:
            busy = (d["unicast"] * timing.bulk_round_trip_s + d["broadcast"] * timing.no_ack_packet_s
                    + d["controls"] * timing.control_transfer_s)
        d.update(broadcast_per_s=d["broadcast"] / span, unicast_per_s=d["unicast"] / span, busy=busy / span)
    return out


def server_pid() -> int:
    import xmlrpc.client

    import rosgraph
    master = rosgraph.Master("/bench_swarm")
    uri = master.lookupNode("/crazyflie_server")
    return int(xmlrpc.client.ServerProxy(uri).getPid("/bench_swarm")[2])


def measure(taps: Taps, names: List[str], ids: Dict[str, int], seconds: float, result: dict,
            inline: bool = False) -> None:
    import rosgraph
    bs.wait_for_ros()
    master = rosgraph.Master("/bench_swarm")
    want = {"/%s/emergency" % n for n in names} | {"/takeoff"}     # /takeoff: all connected and configured
    deadline = time.monotonic() + 300.0
    while time.monotonic() < deadline:
        _, _, srvs = master.getSystemState()
        if want <= {s for s, _ in srvs}:
            break
        time.sleep(0.1)
    else:
        result["error"] = "not every Crazyflie connected within 300 s"
        return
    result["connect_s"] = time.monotonic() - taps.world_listening
    time.sleep(SETTLE_S)
    pid = server_pid()
    cpu_server0, cpu_world0, t0 = bs.process_cpu_seconds(pid), time.process_time(), time.time()
    time.sleep(seconds)
    cpu_server1, cpu_world1, t1 = bs.process_cpu_seconds(pid), time.process_time(), time.time()
    time.sleep(0.5)                         # broadcasts of the last poses
    with taps.lock:
        sent, air = list(taps.sent), list(taps.air)
    result.update(pair(sent, air, ids, t0, t1))
    result["radios"] = {str(k): v for k, v in radio_load(air, t0, t1, inline).items()}
    result["mocap_hz"] = mocap_hz(air, t0, t1)
    result["cpu_server"] = (cpu_server1 - cpu_server0) / (t1 - t0)
    result["cpu_world"] = (cpu_world1 - cpu_world0) / (t1 - t0)


def child(out: str, n: int, seconds: float, toc_cache: str, dongle_model: str = "PA") -> None:
    from crazyflie_demo.swarm_grid import swarm_file_text
    from crazyflie_driver.server.swarm.config import load_swarm_file
    work = tempfile.mkdtemp(prefix="cf_swarm_")
    swarm_file = os.path.join(work, "swarm.yaml")
    with open(swarm_file, "w") as f:
        f.write(swarm_file_text(n))
    swarm = load_swarm_file(swarm_file)
    names = [cf.name for cf in swarm.crazyflies]
    ids = {cf.name: cf.id for cf in swarm.crazyflies}
    taps = Taps()
    taps.install()
    text = launch_text(swarm_file, "127.0.0.1:%d" % bs.free_port(), bs.free_port(), dongle_model)
    inline = dongle_model == "2.0"
    bs.ros_graph_with_sim_node(text, lambda result, _: measure(taps, names, ids, seconds, result, inline), out,
                               prefix="cf_swarm_", env={"CRAZYFLIE_TOC_CACHE": toc_cache} if toc_cache else None)


def main() -> int:
    ap = bs.parser(__doc__, "swarm.txt", 10.0, counts="1,16,49")
    ap.add_argument("--connect", action="store_true", help="also connect each swarm size fresh, then warm")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--n", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--toc-cache", default="", help=argparse.SUPPRESS)
    ap.add_argument("--dongle-model", default="PA", help="the simulated Crazyradio model (PA, PA-99.55, 2.0)")
    args = ap.parse_args()
    if args.child:
        child(args.child, args.n, args.seconds, args.toc_cache, args.dongle_model)
        return 0
    lines = ["swarm mode: world VRPN (100 Hz, poses stamped when sent) -> crazyflie_server -> packed broadcast "
             "on the fake Crazyradios (%s); Crazyflies on the ground, %.0f s measured per case"
             % (args.dongle_model, args.seconds),
             bs.machine_line(), "",
             "%4s %7s %12s %9s %10s %-44s %12s %10s %10s %10s" % (
                 "CFs", "radios", "latency ms", "p99 ms", "unsent %", "per radio: broadcasts/s + unicast/s (busy)",
                 "mocap Hz/CF", "server CPU", "world CPU", "connect s")]
    print("\n".join(lines), flush=True)
    for n in bs.counts_of(args.counts):
        r = bs.run_child(__file__, ["--n", str(n), "--seconds", str(args.seconds), "--dongle-model", args.dongle_model],
                         timeout=args.seconds + 400)
        lines.append(row(n, r))
        print(lines[-1], flush=True)
    for n in bs.counts_of(args.counts) if args.connect else ():
        cache = tempfile.mkdtemp(prefix="cf_swarm_toc_")
        lines += ["", "connect %d Crazyflies (world accepting -> /takeoff registered: all connected, configured):"
                  % n]
        for label in ("empty TOC cache", "warm TOC cache"):
            r = bs.run_child(__file__, ["--n", str(n), "--seconds", "1", "--toc-cache", cache], timeout=900)
            lines.append("  %-16s %s" % (label, "%.1f s" % r["connect_s"] if "connect_s" in r
                                         else "failed: %s" % r.get("error")))
            print(lines[-1], flush=True)
    lines += ["",
              "latency: world VRPN send -> first packed broadcast with that Crazyflie's id and millimetres on the air.",
              "busy: (unicast packets x 0.8 ms bulk round trip + broadcast packets x 0.3 ms air time + address/ack",
              "changes x 1.5 ms control transfer) / time, the fake dongle's timing model (a 2.0 in inline mode: no",
              "control transfer, 0.6 ms a broadcast packet).",
              "mocap Hz/CF: packed-broadcast poses per second of each Crazyflie on the air, lowest-highest.",
              "CPU: share of one core, user + system; server: crazyflie_server process; world: the simulated world",
              "node's process (physics, firmware, VRPN server, and this bench's taps)."]
    bs.write_lines(args.out, lines)
    return 0


def row(n: int, r: dict) -> str:
    lat = r.get("latencies") or []
    if not lat:
        return "%4d   failed: %s" % (n, r.get("error", "no poses paired"))
    radios = r.get("radios", {})
    per = " ".join("%d+%d(%.0f%%)" % (v["broadcast_per_s"], v["unicast_per_s"], 100 * v["busy"])
                   for _, v in sorted(radios.items()))
    unsent = 100.0 * r["missing"] / (r["missing"] + len(lat))
    hz = r.get("mocap_hz") or [float("nan")]
    return "%4d %7d %12.1f %9.1f %10.1f %-44s %12s %9.0f%% %9.0f%% %10.1f" % (
        n, len(radios), 1000 * statistics.median(lat), 1000 * bs.percentile(lat, 99), unsent, per,
        "%.0f-%.0f" % (min(hz), max(hz)),
        100 * r["cpu_server"], 100 * r["cpu_world"], r.get("connect_s", float("nan")))


if __name__ == "__main__":
    sys.exit(main())
