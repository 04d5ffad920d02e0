#!/usr/bin/env python3
"""Round-trip time of one radio packet through RemoteMedium -> world server -> simulated Crazyflie.

Runs a WorldServer in this process on an ephemeral loopback port (the client talks to it over TCP
exactly as another process would) and times N null-packet round trips. Prints median and p99.
Usage: /usr/bin/python3 bench/bench_remote_medium.py [N]
"""
from __future__ import annotations

import statistics
import sys
import time

import bench_support as bs


def main() -> None:
    from crazyflie_driver.sim.air.medium import LocalMedium, RemoteMedium
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 20000
    with bs.served_world([("radio://0/80/2M/E7E7E7E701", "bench")], world=bs.IdleWorld()) as (_, address):
        host, _, port = address.rpartition(":")
        measure(n, RemoteMedium(host, int(port)), LocalMedium)


def measure(n: int, medium, local_medium) -> None:
    addr = bytes.fromhex("E7E7E7E701")
    for _ in range(500):
        medium.transmit(0, 80, 2, addr, b"\xff")
    samples = []
    for _ in range(n):
        t0 = time.perf_counter()
        medium.transmit(0, 80, 2, addr, b"\xff")
        samples.append(time.perf_counter() - t0)
    samples.sort()
    local = local_medium()
    from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie
    local.add_crazyflie(SimulatedCrazyflie(addr, bs.IdleVehicle()), 80, 2)
    t0 = time.perf_counter()
    for _ in range(n):
        local.transmit(0, 80, 2, addr, b"\xff")
    local_us = (time.perf_counter() - t0) / n * 1e6
    print("RemoteMedium round trip over loopback TCP, %d null packets:" % n)
    print("  median %.1f us, p99 %.1f us, max %.1f us" % (
        statistics.median(samples) * 1e6, samples[int(0.99 * (n - 1))] * 1e6, samples[-1] * 1e6))
    print("LocalMedium (in process) reference: %.1f us per round trip" % local_us)
    medium.close()


if __name__ == "__main__":
    main()
