#!/usr/bin/env python3
"""Round-trip time of one radio packet through RemoteMedium -> world server -> simulated Crazyflie,
and the host CPU each one costs.

Runs a WorldServer in this process on an ephemeral loopback port (the client talks to it over TCP
exactly as another process would) and times N null-packet round trips. Prints median and p99. Then
the CPU time (``time.process_time``: this process, the client and the server thread together, so the
figure holds on a busy machine) per request of a null packet to one Crazyflie and of a packed-pose
broadcast heard by 17 (one radio's share of a 49-Crazyflie swarm), and of the world's medium alone.
Usage: /usr/bin/python3 bench/bench_remote_medium.py [N]
"""
from __future__ import annotations

import statistics
import sys
import time
from typing import Callable

import bench_support as bs

LISTENERS = 17          # Crazyflies on one radio's channel at 49 on three radios


def main() -> None:
    from crazyflie_driver.sim.air.medium import LocalMedium, RemoteMedium
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 20000
    with bs.served_world([("radio://0/80/2M/E7E7E7E701", "bench")], world=bs.IdleWorld()) as (_, address):
        host, _, port = address.rpartition(":")
        measure(n, RemoteMedium(host, int(port)), LocalMedium)
    cpu_per_request(n // 4)


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


def cpu_us(call: Callable[[], object], n: int, rounds: int = 3) -> float:
    """CPU microseconds per ``call()`` of this process, the least of ``rounds`` rounds of ``n``."""
    best = float("inf")
    for _ in range(rounds):
        t0 = time.process_time()
        for _ in range(n):
            call()
        best = min(best, time.process_time() - t0)
    return best / n * 1e6


def cpu_per_request(n: int) -> None:
    """Host CPU per radio packet of a swarm on the simulated air: each is one request to the world."""
    from crazyflie_driver.protocol.localization import packed_pose_packets
    from crazyflie_driver.radio.broadcast import BROADCAST_ADDRESS
    from crazyflie_driver.sim.air.medium import RemoteMedium
    from crazyflie_driver.sim.room.world import World
    vehicles = [("radio://0/80/2M/E7E7E7E7%02X" % i, "cf%d" % i, (0.3 * i, 0.0, 0.0)) for i in range(1, LISTENERS + 1)]
    poses = packed_pose_packets([(1, 0.1, 0.2, 0.3, 0.0, 0.0, 0.0, 1.0), (2, 0.4, 0.5, 0.3, 0.0, 0.0, 0.0, 1.0)])
    packet, addr = poses[0].to_bytes(), bytes.fromhex("E7E7E7E701")
    world = World(speed=1.0, seed=3)      # not started: the world's own ticks stay out of the figures
    server_ctx = bs.served_world(vehicles, world=_Unstarted(world))
    with server_ctx as (server, address):
        host, _, port = address.rpartition(":")
        remote = RemoteMedium(host, int(port))
        local = server.medium
        figures = [
            ("world's medium alone, null packet to one Crazyflie", cpu_us(
                lambda: local.transmit(0, 80, 2, addr, b"\xff"), n)),
            ("world's medium alone, packed-pose broadcast to %d" % LISTENERS, cpu_us(
                lambda: local.transmit(0, 80, 2, BROADCAST_ADDRESS, packet, False), n)),
            ("one request over loopback TCP, null packet to one Crazyflie", cpu_us(
                lambda: remote.transmit(0, 80, 2, addr, b"\xff"), n)),
            ("one request over loopback TCP, packed-pose broadcast to %d" % LISTENERS, cpu_us(
                lambda: remote.transmit(0, 80, 2, BROADCAST_ADDRESS, packet, False), n)),
        ]
        remote.close()
    print("Host CPU per radio packet (time.process_time, client and world server together, least of 3 x %d):" % n)
    for what, us in figures:
        print("  %-62s %6.1f us" % (what, us))


class _Unstarted:
    """A world the served_world helper must not start (no ticks: the CPU figures are the packets')."""

    def __init__(self, world) -> None:
        self._world = world

    def __getattr__(self, name: str):
        if name in ("start", "stop"):
            raise AttributeError(name)
        return getattr(self._world, name)


if __name__ == "__main__":
    main()
