#!/usr/bin/env python3
"""Round-trip time of one radio packet through RemoteMedium -> world server -> simulated Crazyflie.

Runs a WorldServer in this process on an ephemeral loopback port (the client talks to it over TCP
exactly as another process would) and times N null-packet round trips. Prints median and p99.
Usage: PYTHONPATH=crazyflie_driver/src python3 bench/sim_remote_medium_rtt.py [N]
"""
from __future__ import annotations

import statistics
import sys
import time


class _Vehicle:
    name = "bench"

    def time(self):
        return time.monotonic()

    def read(self, name):
        return 0.0

    def param_defaults(self):
        return {}

    def write_param(self, name, value):
        pass

    def set_rpyt(self, *args):
        pass

    def emergency_stop(self):
        pass


class _World:
    time = 0.0

    def add_vehicle(self, name, **kw):
        return _Vehicle()

    def add_tick_listener(self, fn, period):
        pass


def main() -> None:
    from crazyflie_driver.sim.air.medium import LocalMedium, RemoteMedium
    from crazyflie_driver.sim.air.server import WorldServer
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 20000
    server = WorldServer(_World(), port=0)
    server.add_crazyflie("radio://0/80/2M/E7E7E7E701")
    host, port = server.start()
    medium = RemoteMedium(host, port)
    addr = bytes.fromhex("E7E7E7E701")
    for _ in range(500):
        medium.transmit(0, 80, 2, addr, b"\xff")
    samples = []
    for _ in range(n):
        t0 = time.perf_counter()
        medium.transmit(0, 80, 2, addr, b"\xff")
        samples.append(time.perf_counter() - t0)
    samples.sort()
    local = LocalMedium()
    from crazyflie_driver.sim.firmware.firmware import SimulatedCrazyflie
    local.add_crazyflie(SimulatedCrazyflie(addr, _Vehicle()), 80, 2)
    t0 = time.perf_counter()
    for _ in range(n):
        local.transmit(0, 80, 2, addr, b"\xff")
    local_us = (time.perf_counter() - t0) / n * 1e6
    print("RemoteMedium round trip over loopback TCP, %d null packets:" % n)
    print("  median %.1f us, p99 %.1f us, max %.1f us" % (
        statistics.median(samples) * 1e6, samples[int(0.99 * (n - 1))] * 1e6, samples[-1] * 1e6))
    print("LocalMedium (in process) reference: %.1f us per round trip" % local_us)
    medium.close()
    server.stop()


if __name__ == "__main__":
    main()
