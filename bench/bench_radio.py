#!/usr/bin/env python3
"""Setpoint throughput and host CPU cost of the radio path through one fake Crazyradio.

For 1, 2, 4 and 8 Crazyflies sharing one dongle, every Crazyflie sends RPYT setpoints (port 3, 15
bytes, safelink on) as fast as the dongle takes them, and the run reports:

* setpoint packets per second (all Crazyflies together, and the slowest one: fairness),
* host CPU time per packet = process CPU time (all threads) / packets acked,
* next to the modelled capacity of the dongle in the same run: 1 / modelled round-trip time, where
  the modelled round trip = bulk OUT+IN time + (control transfers per packet x control-transfer
  time), both from the fake dongle's ``DongleTiming`` and its counters. With more than one Crazyflie
  the dongle must be re-addressed (SET_RADIO_ADDRESS) before nearly every packet.

Two ways to drive the dongle: "threads" (each Crazyflie a ``RadioLink`` sending from its own thread;
the ``SharedRadio`` FIFO lock interleaves them, as the driver's per-Crazyflie workers do) and
"round-robin" (one thread sending to each Crazyflie in turn). Each is run with the default timing
model (PA: 0.8 ms per bulk round trip, 1.5 ms per control transfer, real sleeps) and with the model
off (no sleeps: pure host overhead).

First, the Crazyflie level, one Crazyflie, timing model off: host CPU per RPYT setpoint of
``Crazyflie.send_setpoint`` (value checks, packet building, ``RadioLink``, the dongle, the simulated
firmware) beside Bitcraze's cflib doing the same in the same run (``bench_radio_cflib.py``, run with
cflib's interpreter: ``.ws/cflib-venv``, or $CFLIB_PYTHON). Both count the setpoints the simulated
commander received and the CPU time of the whole process, on the same fake dongle and idle simulated
Crazyflie with the timing model off, and start after connecting (cflib: once its parameter values are
in). They alternate (``--rounds``, ours then cflib's in each), so that both see the same load of a
shared machine; the medians are compared.

The path measured is the real one from ``RadioLink.send_bytes`` down: safelink bits, ``SharedRadio``,
``Crazyradio`` (pyusb ``write``/``read``, vendor requests), the fake pyusb backend, ``LocalMedium`` and the
simulated nRF + commander port of ``SimulatedCrazyflie`` (a vehicle that does nothing, so physics does
not enter the figures), all in this process. Usage:
    /usr/bin/python3 bench/bench_radio.py [--seconds 2] [--rounds 3] [--modes none] [--out FILE]
"""
from __future__ import annotations

import json
import math
import os
import statistics
import struct
import subprocess
import sys
import threading
import time
from typing import List, Optional, Tuple

import bench_support as bs
from bench_support import IdleVehicle
from crazyflie_driver.protocol.crazyflie import Crazyflie
from crazyflie_driver.radio.link import RadioLink
from crazyflie_driver.radio.shared_radio import RadioManager
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from crazyflie_driver.sim.air.medium import LocalMedium
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie

SETPOINT = bytes([0x30]) + struct.pack("<fffH", 0.0, 0.0, 0.0, 0)   # port 3 ch 0 RPYT, thrust 0
WARMUP_S = 0.2


CFLIB_PYTHON = os.environ.get("CFLIB_PYTHON") or os.path.join(bs.REPO, ".ws", "cflib-venv", "bin", "python3")


def crazyflie_level(seconds: float) -> dict:
    """``Crazyflie.send_setpoint`` in a loop on one fake dongle, timing model off: CPU per setpoint."""
    medium = LocalMedium(dongles=1, seed=1)
    sim = SimulatedCrazyflie(bytes([0xE7] * 5), IdleVehicle())
    medium.add_crazyflie(sim, 80, 2)
    backend = FakeUsbBackend(medium, dongles=1, timing=DongleTiming.instant())
    cf = Crazyflie("radio://0/80/2M/E7E7E7E7E7", RadioManager(backend=backend))
    cf.connect()
    send = cf.send_setpoint
    try:
        end = time.monotonic() + WARMUP_S
        while time.monotonic() < end:
            send(0.0, 0.0, 0.0, 0)
        s0, r0, cpu0, t0 = sim.state.setpoints, sim.state.rx_unicast, time.process_time(), time.monotonic()
        end = t0 + seconds
        while time.monotonic() < end:
            for _ in range(100):
                send(0.0, 0.0, 0.0, 0)
        s1, r1, cpu1, t1 = sim.state.setpoints, sim.state.rx_unicast, time.process_time(), time.monotonic()
    finally:
        cf.close()
    setpoints = s1 - s0
    return {"setpoints": setpoints, "seconds": t1 - t0, "cpu_us": 1e6 * (cpu1 - cpu0) / setpoints,
            "packets_per_setpoint": (r1 - r0) / setpoints}


def cflib_level(seconds: float) -> Optional[dict]:
    """cflib's figure from ``bench_radio_cflib.py`` in its own interpreter; None (with the reason
    printed) when cflib is not installed or its run failed."""
    if not os.path.exists(CFLIB_PYTHON):
        print("cflib not measured: no %s (tools/bootstrap.sh --with-cflib, or set CFLIB_PYTHON)" % CFLIB_PYTHON)
        return None
    script = os.path.join(bs.HERE, "bench_radio_cflib.py")
    run = subprocess.run([CFLIB_PYTHON, script, "--seconds", str(seconds), "--warmup", str(WARMUP_S)],
                         capture_output=True, text=True,
                         timeout=60 + 2 * seconds)
    if run.returncode != 0:
        print("cflib not measured: %s exited with %d:\n%s" % (script, run.returncode, run.stderr[-2000:]))
        return None
    return json.loads(run.stdout.strip().splitlines()[-1])


def both_levels(seconds: float, rounds: int) -> Tuple[List[dict], List[dict]]:
    """Ours and cflib's, one after the other ``rounds`` times, so that both see the same load of a
    shared machine; cflib's list is empty when it could not be measured."""
    ours: List[dict] = []
    theirs: List[dict] = []
    for _ in range(rounds):
        ours.append(crazyflie_level(seconds))
        one = cflib_level(seconds)
        if one is None or not one.get("cpu_us"):
            return ours, []
        theirs.append(one)
    return ours, theirs


def level_lines(seconds: float, ours: List[dict], theirs: List[dict]) -> List[str]:
    """The Crazyflie level's lines: the median round of each, the ratio of the medians and its range
    over the rounds."""
    mine = statistics.median(r["cpu_us"] for r in ours)
    first = ours[0]
    lines = ["Crazyflie level, one Crazyflie, timing model off, %d rounds of %.1f s after %.1f s warm-up, ours"
             % (len(ours), seconds, WARMUP_S),
             "then cflib's in each (host CPU per setpoint the simulated commander received, whole process;",
             "median of the rounds, their range in brackets; radio packets per setpoint: all the simulated",
             "Crazyflie received / setpoints):",
             "  ours  Crazyflie.send_setpoint             %6.1f us/setpoint  [%.1f-%.1f]  (%d setpoints/s,"
             " %.2f packets/setpoint)"
             % (mine, min(r["cpu_us"] for r in ours), max(r["cpu_us"] for r in ours),
                first["setpoints"] / first["seconds"], first["packets_per_setpoint"])]
    if not theirs:
        return lines + ["  cflib: not measured (see above)"]
    cflib = statistics.median(r["cpu_us"] for r in theirs)
    ratios = [a["cpu_us"] / b["cpu_us"] for a, b in zip(ours, theirs)]
    one = theirs[0]
    return lines + [
        "  cflib %-6s commander.send_setpoint      %6.1f us/setpoint  [%.1f-%.1f]  (%d setpoints/s,"
        " %.2f packets/setpoint, Python %s)"
        % (one["cflib"], cflib, min(r["cpu_us"] for r in theirs), max(r["cpu_us"] for r in theirs),
           one["setpoints"] / one["seconds"], one["packets_per_setpoint"], one["python"]),
        "  ours / cflib = %.3f  [%.3f-%.3f over the rounds]" % (mine / cflib, min(ratios), max(ratios))]


def _open_links(n: int, timing: DongleTiming) -> Tuple[FakeUsbBackend, List[SimulatedCrazyflie], List[RadioLink]]:
    """``n`` simulated Crazyflies (addresses E7E7E7E701..) on one fake dongle, a safelink ``RadioLink`` to each."""
    medium = LocalMedium(dongles=1, seed=1)
    sims = []
    for i in range(n):
        cf = SimulatedCrazyflie(bytes([0xE7, 0xE7, 0xE7, 0xE7, i + 1]), IdleVehicle())
        medium.add_crazyflie(cf, 80, 2)
        sims.append(cf)
    backend = FakeUsbBackend(medium, dongles=1, timing=timing)
    manager = RadioManager(backend=backend)
    links = [RadioLink("radio://0/80/2M/E7E7E7E7%02X" % (i + 1), manager) for i in range(n)]
    for link in links:
        link.open()
    assert all(link.safelink for link in links), "safelink was not negotiated"
    return backend, sims, links


def _senders(links: List[RadioLink], mode: str, counts: List[int], failures: List[int],
             stop: threading.Event) -> List[threading.Thread]:
    """The sending threads: one per link ("threads") or one for all in turn ("round-robin")."""
    def send_until_stopped(indexes: List[int]) -> None:
        sends = [(i, links[i].send_bytes) for i in indexes]
        while not stop.is_set():
            for i, send in sends:
                if send(SETPOINT):
                    counts[i] += 1
                else:
                    failures[i] += 1

    groups = [[i] for i in range(len(links))] if mode == "threads" else [list(range(len(links)))]
    return [threading.Thread(target=send_until_stopped, args=(group,), daemon=True) for group in groups]


def run_case(n: int, timing: DongleTiming, mode: str, seconds: float) -> dict:
    backend, sims, links = _open_links(n, timing)
    counts: List[int] = [0] * n
    failures: List[int] = [0] * n
    stop = threading.Event()
    threads = _senders(links, mode, counts, failures, stop)
    for t in threads:
        t.start()
    time.sleep(WARMUP_S)
    dongle = backend.dongles[0]
    c0, ctrl0, setp0 = list(counts), dongle.control_transfers, [s.state.setpoints for s in sims]
    cpu0, t0 = time.process_time(), time.monotonic()
    time.sleep(seconds)
    cpu1, t1 = time.process_time(), time.monotonic()
    c1, ctrl1, setp1 = list(counts), dongle.control_transfers, [s.state.setpoints for s in sims]
    stop.set()
    for t in threads:
        t.join(5.0)
    for link in links:
        link.close()
    elapsed = t1 - t0
    packets = sum(c1) - sum(c0)
    if not packets:
        return {"n": n, "mode": mode, "rate": 0.0, "rate_min": 0.0, "cpu_us": math.nan,
                "cpu_share": (cpu1 - cpu0) / elapsed, "ctrl_per_packet": math.nan, "modelled_rtt_ms": math.nan,
                "capacity": math.nan, "failures": sum(failures), "delivered_ratio": 0.0}
    ctrl_per_packet = (ctrl1 - ctrl0) / packets
    modelled_rtt = timing.bulk_round_trip_s + ctrl_per_packet * timing.control_transfer_s
    return {"n": n, "mode": mode, "rate": packets / elapsed,
            "rate_min": min((b - a) / elapsed for a, b in zip(c0, c1)),
            "cpu_us": 1e6 * (cpu1 - cpu0) / packets, "cpu_share": (cpu1 - cpu0) / elapsed,
            "ctrl_per_packet": ctrl_per_packet, "modelled_rtt_ms": 1000.0 * modelled_rtt,
            "capacity": 1.0 / modelled_rtt if modelled_rtt > 0 else float("inf"),
            "failures": sum(failures), "delivered_ratio": (sum(setp1) - sum(setp0)) / packets}


def main() -> int:
    ap = bs.parser(__doc__, "radio.txt", 2.0, counts="1,2,4,8")
    ap.add_argument("--modes", default="threads,round-robin", help="link-level modes; none: only the Crazyflie level")
    ap.add_argument("--rounds", type=int, default=3, help="Crazyflie level: rounds of ours then cflib's (median)")
    args = ap.parse_args()
    model = DongleTiming()
    ours, theirs = both_levels(args.seconds, args.rounds)
    level = level_lines(args.seconds, ours, theirs)
    table = bs.Table(
        level + ["", "Link level: RPYT setpoints through one fake Crazyradio PA (RadioLink with safelink ->",
         "Crazyradio -> pyusb -> FakeUsbBackend -> LocalMedium -> simulated nRF + commander),",
         "%.1f s per case after %.1f s warm-up" % (args.seconds, WARMUP_S),
         "timing model: bulk round trip %.2f ms, control transfer %.2f ms; 'off' = DongleTiming.instant()"
         % (1000 * model.bulk_round_trip_s, 1000 * model.control_transfer_s),
         bs.machine_line(),
         ""],
        [("timing", "<6"), ("mode", "<11"), ("CFs", "3d"), ("packets/s", "10.0f"), ("slowest CF/s", "12.0f"),
         ("CPU us/packet", "13.1f"), ("CPU load", "9.0%"), ("ctrl/packet", "12.2f"), ("model RTT ms", "12.2f"),
         ("capacity/s", "10.0f")])
    for label, timing in (("model", model), ("off", DongleTiming.instant())):
        for mode in args.modes.split(","):
            for n in bs.counts_of(args.counts):
                if mode == "none":
                    continue
                r = run_case(n, timing, mode, args.seconds)
                if r["failures"] or abs(r["delivered_ratio"] - 1.0) > 0.01:
                    print("warning: %d unacked, delivered/acked = %.3f" % (r["failures"], r["delivered_ratio"]))
                modelled = label == "model"
                table.row(label, mode, n, r["rate"], r["rate_min"], r["cpu_us"], r["cpu_share"],
                          r["ctrl_per_packet"], r["modelled_rtt_ms"] if modelled else 0.0,
                          r["capacity"] if modelled else None)
    table.write(args.out, [
        "packets/s: acked setpoints of all Crazyflies together (each was delivered to the simulated",
        "commander once: safelink drops duplicates). CPU us/packet: process CPU time (all threads) /",
        "packets. capacity/s = 1 / model RTT, model RTT = bulk round trip + ctrl/packet x control transfer."])
    return 0


if __name__ == "__main__":
    sys.exit(main())
