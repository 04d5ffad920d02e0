#!/usr/bin/env python3
"""Onboard flight of the simulated Crazyflie: hover error under the onboard PID position controller
fed by motion capture, its dependence on the mocap rate, what a mocap outage does, and the world's
real-time factor with 49 vehicles under onboard control.

Every flight goes through the simulated firmware's ports: the world's motion-capture model
(MocapModel defaults: 0.5 mm / 0.2 deg white noise, 8 ms latency; seeded) is sent as port-6
external positions, position setpoints (0, 0, 0.5) as port-7 type 7 at 50 Hz, with
stabilizer.estimator 2 and stabilizer.controller 1. Errors are of the world's true position, over a
10 s hold that starts 12 s after the first setpoint (the take-off from the floor overshoots and the
z integrators ring down first). The world is stepped by this script (speed 0), so runs are
deterministic per seed.
Run: /usr/bin/python3 bench/bench_onboard.py   (writes bench/results/onboard.txt)
"""
from __future__ import annotations

import argparse
import os
import platform
import struct
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "crazyflie_driver", "src"))

from crazyflie_driver.sim.firmware.firmware import SimulatedCrazyflie  # noqa: E402
from crazyflie_driver.sim.firmware.setpoint_decode import decode_setpoint  # noqa: E402
from crazyflie_driver.sim.world.mocap import MocapModel  # noqa: E402
from crazyflie_driver.sim.world.world import World  # noqa: E402

GOAL = (0.0, 0.0, 0.5)
SETTLE_S = 12.0
HOLD_S = 10.0


def flight(rate_hz: float, std_dev: float, seed: int, outage_s: float = 0.0):
    world = World(speed=0, seed=seed)
    vehicle = world.add_vehicle("cf1")
    cf = SimulatedCrazyflie(b"\xe7\xe7\xe7\xe7\x01", vehicle)
    mocap = MocapModel(world, rate=rate_hz, seed=seed).attach()
    blackout = [None, None]

    def on_frames(frames):
        if blackout[0] is not None and blackout[0] <= world.time < blackout[1]:
            return
        for f in frames:
            cf.handle_crtp(bytes([0x6C]) + struct.pack("<fff", *f.position))

    mocap.add_listener(on_frames)
    setpoint = bytes([0x7C, 7]) + struct.pack("<ffff", GOAL[0], GOAL[1], GOAL[2], 0.0)
    world.add_tick_listener(lambda now: cf.handle_crtp(setpoint), 0.02)
    for name, value in (("stabilizer.estimator", 2), ("stabilizer.controller", 1), ("locSrv.extPosStdDev", std_dev)):
        vehicle.write_param(name, value)
        cf.params.values[cf.params.ident(name)] = value
    t0 = time.perf_counter()
    world.step(int(SETTLE_S * 1000))
    errors, path = [], []
    if outage_s:
        blackout[:] = [world.time, world.time + outage_s]
    for _ in range(int(HOLD_S * 100)):
        world.step(10)
        p = vehicle.pose()[0]
        errors.append(p - GOAL)
        path.append(world.time)
    wall = time.perf_counter() - t0
    e = np.array(errors)
    norm = np.linalg.norm(e, axis=1)
    out = {"mean_mm": 1000 * norm.mean(), "rms_mm": 1000 * np.sqrt((norm ** 2).mean()), "max_mm": 1000 * norm.max(),
           "rtf": (SETTLE_S + HOLD_S) / wall, "halted": cf.state.halted}
    if outage_s:
        horizontal = np.linalg.norm(e[:, :2], axis=1)
        t = np.array(path) - blackout[0]
        during = horizontal[t < outage_s]
        after = horizontal[(t >= outage_s + 3.0)]
        out.update(outage_max_mm=1000 * during.max(), outage_end_mm=1000 * during[-1],
                   recovered_mm=1000 * after.max() if len(after) else float("nan"))
    return out


def fleet_rtf(n: int, onboard: bool, seconds: float = 2.0) -> float:
    """World.step alone (no radio) for n vehicles, RPYT hover thrust or onboard PID with extpos."""
    world = World(speed=0, seed=1)
    vehicles = [world.add_vehicle("cf%d" % i, position=(i % 7 * 0.5, i // 7 * 0.5, 0.0)) for i in range(n)]
    for v in vehicles:
        if onboard:
            v.write_param("stabilizer.estimator", 2)
            p = v.pose()[0]
            v.set_setpoint(decode_setpoint(bytes([7]) + struct.pack("<ffff", p[0], p[1], 0.5, 0.0)))
        else:
            v.set_rpyt(0.0, 0.0, 0.0, 0)
            v.set_rpyt(0.0, 0.0, 0.0, 36000)

    def feed(now):
        if onboard:
            for v in vehicles:
                v.external_measurement(v.pose()[0])
    world.add_tick_listener(feed, 0.01)
    world.step(500)
    t0 = time.perf_counter()
    world.step(int(seconds * 1000))
    return seconds / (time.perf_counter() - t0)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--out", default=os.path.join(HERE, "results", "onboard.txt"))
    args = p.parse_args()
    lines = ["onboard hover at (0, 0, 0.5): estimator 2 + PID position controller (controller 1), firmware defaults",
             "mocap: MocapModel (0.5 mm / 0.2 deg noise, 8 ms latency) sent as port-6 extpos; "
             "setpoints type 7 at 50 Hz",
             "errors of the true position over %.0f s, from %.0f s after the first setpoint; seed %d"
             % (HOLD_S, SETTLE_S, args.seed),
             "%-8s %-12s %9s %9s %9s %9s" % ("mocap Hz", "extPosStdDev", "mean_mm", "rms_mm", "max_mm", "world/wall")]
    for rate, std in ((100.0, 0.01), (100.0, 0.001), (10.0, 0.01), (2.0, 0.01)):
        r = flight(rate, std, args.seed)
        lines.append("%-8g %-12g %9.2f %9.2f %9.2f %8.2fx"
                     % (rate, std, r["mean_mm"], r["rms_mm"], r["max_mm"], r["rtf"]))
        print(lines[-1], flush=True)
    lines.append("mocap outage while hovering (100 Hz before and after): horizontal error of the true position")
    lines.append("%-8s %16s %16s %22s" % ("outage s", "max during mm", "at its end mm", "max from +3 s after mm"))
    for outage in (1.0, 5.0):
        r = flight(100.0, 0.01, args.seed, outage)
        lines.append("%-8g %16.1f %16.1f %22.1f" % (outage, r["outage_max_mm"], r["outage_end_mm"], r["recovered_mm"]))
        print(lines[-1], flush=True)
    lines.append("World.step real-time factor "
                 "(no radio; onboard: extpos for every vehicle at 100 Hz via the Vehicle API)")
    lines.append("%-9s %10s %10s" % ("vehicles", "RPYT", "onboard PID"))
    for n in (1, 10, 49):
        lines.append("%-9d %9.2fx %9.2fx" % (n, fleet_rtf(n, False), fleet_rtf(n, True)))
        print(lines[-1], flush=True)
    lines.append("machine: %s, Python %s, %d CPUs, load average %.1f"
                 % (platform.machine(), platform.python_version(), os.cpu_count() or 0, os.getloadavg()[0]))
    lines.append("command: /usr/bin/python3 bench/bench_onboard.py")
    with open(args.out, "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
