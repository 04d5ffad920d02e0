#!/usr/bin/env python3
"""CPU cost of the simulated world's ``World.step``: 1, 10, 49 and 100 vehicles in each onboard mode.

Modes: "RPYT" (the chapter's: hover thrust from the host, attitude and rate PIDs on board),
"PID" (onboard PID position controller, estimator 2 fed external positions) and "Mellinger"
(controller 2, estimator 2). Host traffic is played at 100 Hz of world time from a tick listener,
through the Vehicle API as the simulated firmware would deliver it (no radio): RPYT setpoints, or
position setpoints plus an external position per vehicle. The figure is the CPU time of the stepping
thread (``time.thread_time``) per second of world time, so a busy machine does not distort it the
way wall time would: "real-time factor" is world seconds per CPU second (how fast the world runs on
one free core, fast mode), "% of a core at speed 1" its inverse. Writes bench/results/world.txt.
Run: /usr/bin/python3 bench/bench_world.py
"""
from __future__ import annotations

import argparse
import os
import platform
import struct
import time

HERE = os.path.dirname(os.path.abspath(__file__))

import bench_support  # noqa: E402,F401  (the sources and the tests' support on the path)
from crazyflie_driver.sim.crtp.setpoint_decode import decode_setpoint  # noqa: E402
from crazyflie_driver.sim.room.physics import VehicleParams  # noqa: E402
from crazyflie_driver.sim.room.world import World  # noqa: E402

FLEETS = (1, 10, 49, 100)
MODES = ("RPYT", "PID", "Mellinger")
HEIGHT = 1.0                                       # m
SIM_SECONDS = 3.0
REPEATS = 3


def fleet(n: int, mode: str) -> World:
    """n vehicles hovering at HEIGHT in ``mode``, host traffic at 100 Hz, warmed up."""
    w = World(speed=0, seed=1)
    vehicles = [w.add_vehicle("cf%d" % i, position=(i % 10 * 0.5, i // 10 * 0.5, HEIGHT)) for i in range(n)]
    hover = int(round(VehicleParams().hover_command()))
    if mode == "RPYT":
        for v in vehicles:
            v.set_rpyt(0, 0, 0, 0)                 # unlocks the thrust

        def traffic(now: float) -> None:
            for v in vehicles:
                v.set_rpyt(0.0, 0.0, 0.0, hover)
    else:
        setpoints = []
        for v in vehicles:
            v.write_param("stabilizer.estimator", 2)
            v.write_param("kalman.initialX", v.pose()[0][0])
            v.write_param("kalman.initialY", v.pose()[0][1])
            v.write_param("kalman.initialZ", HEIGHT)
            v.write_param("kalman.resetEstimation", 1)
            v.write_param("stabilizer.controller", 2 if mode == "Mellinger" else 1)
            p = v.pose()[0]
            setpoints.append(decode_setpoint(bytes([7]) + struct.pack("<ffff", p[0], p[1], HEIGHT, 0.0)))

        def traffic(now: float) -> None:
            for v, sp in zip(vehicles, setpoints):
                v.external_measurement(v.pose()[0])
                v.set_setpoint(sp)
    traffic(0.0)
    w.step(2)
    w.bodies.thrust[:] = VehicleParams().thrust(hover)     # rotors already at hover speed
    w.add_tick_listener(traffic, 0.01)
    w.step(500)                                    # warm up, motors at speed
    return w


def measure(n: int, mode: str, seconds: float = SIM_SECONDS, repeats: int = REPEATS) -> dict:
    w = fleet(n, mode)
    ticks = int(seconds * 1000)
    best = float("inf")
    for _ in range(repeats):                       # best of: the least disturbed by other processes
        c0 = time.thread_time()
        w.step(ticks)
        best = min(best, time.thread_time() - c0)
    flying = sum(1 for v in w.vehicles() if v.pose()[0][2] > 0.5 * HEIGHT)
    return {"n": n, "rtf": seconds / best, "tick_us": best / ticks * 1e6, "core": 100.0 * best / seconds,
            "flying": flying}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=SIM_SECONDS, help="world seconds per measurement")
    ap.add_argument("--modes", nargs="+", default=list(MODES), choices=MODES)
    ap.add_argument("--fleets", nargs="+", type=int, default=list(FLEETS))
    ap.add_argument("--no-write", action="store_true", help="print only, keep bench/results/world.txt")
    args = ap.parse_args()
    lines = ["World.step CPU cost (fast mode: speed 0; best of %d x %.0f s of world time; 1 kHz firmware ticks; "
             "hovering vehicles, host traffic at 100 Hz; CPU time of the stepping thread)" % (REPEATS, args.seconds),
             "machine: %s, %s, Python %s, %d CPUs, load average %.1f"
             % (platform.machine(), platform.processor() or platform.system(), platform.python_version(),
                os.cpu_count() or 0, os.getloadavg()[0]),
             "%8s %10s %12s %12s %18s %8s" % ("vehicles", "mode", "real-time", "us per tick", "% core at speed 1",
                                              "flying")]
    print("\n".join(lines), flush=True)
    for mode in args.modes:
        for n in args.fleets:
            r = measure(n, mode, args.seconds)
            lines.append("%8d %10s %11.1fx %12.1f %18.1f %8d" % (r["n"], mode, r["rtf"], r["tick_us"], r["core"],
                                                                r["flying"]))
            print(lines[-1], flush=True)
    lines.append("modes: RPYT = the chapter's (host thrust, onboard attitude/rate PIDs); PID = onboard position PID, "
                 "estimator 2 with external positions; Mellinger = controller 2, estimator 2")
    lines.append("command: /usr/bin/python3 bench/bench_world.py")
    if not args.no_write:
        os.makedirs(os.path.join(HERE, "results"), exist_ok=True)
        with open(os.path.join(HERE, "results", "world.txt"), "w") as f:
            f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
