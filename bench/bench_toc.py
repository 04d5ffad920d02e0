#!/usr/bin/env python3
"""Connect + both TOCs through the fake Crazyradio (its default timing model, ~1 ms per round
trip) and the simulated firmware: first connect (download item by item) vs. second connect
(TOC cache hit), for both firmware generations. Prints seconds and radio round trips."""
from __future__ import annotations

import os
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))

import bench_support  # noqa: E402,F401  (the sources and the tests' support on the path)
from crazyflie_driver.protocol.crazyflie import Crazyflie  # noqa: E402
from crazyflie_driver.radio.shared_radio import RadioManager  # noqa: E402
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend  # noqa: E402
from crazyflie_driver.sim.air.medium import LocalMedium  # noqa: E402
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie  # noqa: E402

URI = "radio://0/80/2M/E7E7E7E701"


class Still:
    name = "cf"

    def time(self):
        return time.monotonic()

    def read(self, name):
        return 0.0

    def param_defaults(self):
        return {}

    def write_param(self, name, value):
        pass


def connect_and_fetch(manager, cache_dir):
    cf = Crazyflie(URI, radio_manager=manager, cache_dir=cache_dir)
    start = time.monotonic()
    cf.connect()
    n_params = len(cf.params.fetch_toc())
    n_logs = len(cf.log.fetch_toc())
    elapsed = time.monotonic() - start
    trips = cf.link.stats.sent
    cf.close()
    return elapsed, trips, n_params, n_logs


def main():
    for generation in ("current", "2016.02"):
        medium = LocalMedium(dongles=1, seed=1)
        medium.add_crazyflie(SimulatedCrazyflie(bytes.fromhex("E7E7E7E701"), Still(), generation), 80, 2)
        manager = RadioManager(backend=FakeUsbBackend(medium))
        cache = tempfile.mkdtemp(prefix="bench-toc-")
        t1, r1, np_, nl = connect_and_fetch(manager, cache)
        t2, r2, _, _ = connect_and_fetch(manager, cache)
        print("%-8s %3d params %3d log vars | download: %.3f s, %4d round trips | cached: %.3f s, %3d round trips"
              % (generation, np_, nl, t1, r1, t2, r2))


if __name__ == "__main__":
    main()
