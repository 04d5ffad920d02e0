#!/usr/bin/env python3
"""CPU cost of the simulated world's ``World.step`` for 1, 2, 10, 49 and 100 hovering vehicles.

Each vehicle hovers on its hover thrust; setpoints are refreshed at 100 Hz of world time (as a
radio would) from a tick listener. The figure is the CPU time of the stepping thread
(``time.thread_time``) per second of world time, so a busy machine does not distort it the way wall
time would: "real-time factor" is world seconds per CPU second (how fast the world runs on one
free core), "% of a core at speed 1" is its inverse. With ``--mocap`` a MocapModel (100 Hz) is
attached too. Writes the table to bench/results/world.txt.
Run: /usr/bin/python3 bench/bench_world.py
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "crazyflie_driver", "src"))

from crazyflie_driver.sim.world.mocap import MocapModel  # noqa: E402
from crazyflie_driver.sim.world.physics import VehicleParams  # noqa: E402
from crazyflie_driver.sim.world.world import World  # noqa: E402

FLEETS = (1, 2, 10, 49, 100)
SIM_SECONDS = 5.0
REPEATS = 3


def measure(n: int, mocap: bool, seconds: float = SIM_SECONDS, repeats: int = REPEATS) -> dict:
    w = World(speed=0, seed=1)
    vehicles = [w.add_vehicle("cf%d" % i, position=(i % 10, i // 10, 1.0)) for i in range(n)]
    hover = int(round(VehicleParams().hover_command()))
    for v in vehicles:
        v.set_rpyt(0, 0, 0, 0)
    w.step(2)
    w.bodies.thrust[:] = VehicleParams().thrust(hover)     # rotors already at hover speed

    def refresh(t: float) -> None:
        for v in vehicles:
            v.set_rpyt(0.0, 0.0, 0.0, hover)
    w.add_tick_listener(refresh, 0.01)
    if mocap:
        MocapModel(w, seed=2).attach()
    w.step(200)                                    # warm up, motors at speed
    ticks = int(seconds * 1000)
    best = float("inf")
    for _ in range(repeats):                       # best of: the least disturbed by other processes
        c0 = time.thread_time()
        w.step(ticks)
        best = min(best, time.thread_time() - c0)
    flying = sum(1 for v in vehicles if v.pose()[0][2] > 0.2)
    return {"n": n, "rtf": seconds / best, "tick_us": best / ticks * 1e6, "core": 100.0 * best / seconds,
            "flying": flying}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=SIM_SECONDS, help="world seconds per measurement")
    ap.add_argument("--no-write", action="store_true", help="print only, keep bench/results/world.txt")
    args = ap.parse_args()
    lines = ["World.step CPU cost (speed 0, best of %d x %.0f s of world time, 1 kHz firmware ticks, hovering "
             "vehicles, setpoints at 100 Hz; CPU time of the stepping thread)" % (REPEATS, args.seconds),
             "machine: %s, %s, Python %s, %d CPUs, load average %.1f"
             % (platform.machine(), platform.processor() or platform.system(), platform.python_version(),
                os.cpu_count() or 0, os.getloadavg()[0]),
             "%8s %6s %12s %12s %18s %8s" % ("vehicles", "mocap", "real-time", "us per tick", "% core at speed 1",
                                             "flying")]
    print("\n".join(lines), flush=True)
    for mocap in (False, True):
        for n in FLEETS:
            r = measure(n, mocap, args.seconds)
            lines.append("%8d %6s %11.1fx %12.1f %18.1f %8d" % (r["n"], "100Hz" if mocap else "-", r["rtf"],
                                                               r["tick_us"], r["core"], r["flying"]))
            print(lines[-1], flush=True)
    lines.append("command: /usr/bin/python3 bench/bench_world.py")
    if not args.no_write:
        os.makedirs(os.path.join(HERE, "results"), exist_ok=True)
        with open(os.path.join(HERE, "results", "world.txt"), "w") as f:
            f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
