#!/usr/bin/env python3
"""Real-time factor of the simulated world's `World.step` for 1, 10, 49 and 100 hovering vehicles.

Each vehicle hovers on its hover thrust; setpoints are refreshed at 100 Hz of world time (as a
radio would) from a tick listener. Prints one line per fleet size and writes the table to
bench/results/world.txt. Run: PYTHONPATH=crazyflie_driver/src python3 bench/bench_world.py
"""
from __future__ import annotations

import os
import platform
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "crazyflie_driver", "src"))

from crazyflie_driver.sim.world.physics import VehicleParams  # noqa: E402
from crazyflie_driver.sim.world.world import World  # noqa: E402

FLEETS = (1, 10, 49, 100)
SIM_SECONDS = 3.0


def measure(n: int) -> dict:
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
    w.step(200)                                    # warm up, motors at speed
    ticks = int(SIM_SECONDS * 1000)
    t0 = time.perf_counter()
    w.step(ticks)
    wall = time.perf_counter() - t0
    flying = sum(1 for v in vehicles if v.pose()[0][2] > 0.2)
    return {"n": n, "rtf": SIM_SECONDS / wall, "tick_us": wall / ticks * 1e6,
            "per_vehicle_us": wall / ticks / n * 1e6, "flying": flying}


def main() -> None:
    lines = ["World.step real-time factor (speed 0, %.0f s of world time, 1 kHz ticks, hovering vehicles)"
             % SIM_SECONDS,
             "machine: %s, %s, Python %s, %d CPUs" % (platform.machine(), platform.processor() or platform.system(),
                                                     platform.python_version(), os.cpu_count() or 0),
             "%8s %10s %12s %18s %8s" % ("vehicles", "real-time", "us per tick", "us per vehicle-tick", "flying")]
    for n in FLEETS:
        r = measure(n)
        lines.append("%8d %9.1fx %12.1f %18.2f %8d" % (r["n"], r["rtf"], r["tick_us"], r["per_vehicle_us"],
                                                      r["flying"]))
        print(lines[-1] if len(lines) > 4 else "\n".join(lines), flush=True)
    os.makedirs(os.path.join(HERE, "results"), exist_ok=True)
    with open(os.path.join(HERE, "results", "world.txt"), "w") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
