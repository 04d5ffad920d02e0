#!/usr/bin/env python3
"""cflib's side of ``bench_radio``'s Crazyflie-level case: host CPU per RPYT setpoint of Bitcraze's cflib
flying the same fake Crazyradio PA and simulated Crazyflie, timing model off, printed as one JSON line.

cflib's own Crazyradio driver talks to ``FakeUsbBackend`` (``usb.core.find`` redirected, as the cflib peer
tests do), on a ``LocalMedium`` in this process with the same idle vehicle as ours. The setpoints counted
are the ones the simulated commander port received (cflib sends asynchronously from its radio thread, so
its queue is not a measure); the CPU time is the whole process's (all threads), as for ours.
Run by ``bench_radio.py`` with cflib's interpreter (cflib >= 0.1.28 needs Python >= 3.10):
    .ws/cflib-venv/bin/python3 bench/bench_radio_cflib.py --seconds 2
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from importlib import metadata

import bench_support  # noqa: F401  (the sources and the test support on the path)
from bench_support import IdleVehicle
from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from crazyflie_driver.sim.air.medium import LocalMedium
from crazyflie_driver.sim.crtp.firmware import SimulatedCrazyflie
from support.cflib_find_patch import install_find_patch

URI = "radio://0/80/2M/E7E7E7E7E7"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.strip().split("\n")[0])
    ap.add_argument("--seconds", type=float, default=2.0, help="measured time, s")
    ap.add_argument("--warmup", type=float, default=0.2, help="setpoints before the measurement, s")
    args = ap.parse_args()
    medium = LocalMedium(dongles=1, seed=1)
    sim = SimulatedCrazyflie(bytes([0xE7] * 5), IdleVehicle())
    medium.add_crazyflie(sim, 80, 2)
    install_find_patch(FakeUsbBackend(medium, dongles=1, timing=DongleTiming.instant()))

    import cflib.crtp
    from cflib.crazyflie import Crazyflie
    from cflib.crazyflie.syncCrazyflie import SyncCrazyflie

    cflib.crtp.init_drivers()
    cf = Crazyflie(rw_cache=tempfile.mkdtemp(prefix="bench-radio-cflib-"))
    with SyncCrazyflie(URI, cf=cf) as scf:
        # Connected means the TOCs are in; the parameter values still download in the background
        # (about 280 requests): measured, they would count against cflib's setpoints.
        scf.wait_for_params()
        send = scf.cf.commander.send_setpoint
        send(0, 0, 0, 0)
        end = time.monotonic() + args.warmup
        while time.monotonic() < end:
            send(0.0, 0.0, 0.0, 0)
        s0, r0, cpu0, t0 = sim.state.setpoints, sim.state.rx_unicast, time.process_time(), time.monotonic()
        end = t0 + args.seconds
        while time.monotonic() < end:
            for _ in range(100):
                send(0.0, 0.0, 0.0, 0)
        s1, r1, cpu1, t1 = sim.state.setpoints, sim.state.rx_unicast, time.process_time(), time.monotonic()
    setpoints = s1 - s0
    print(json.dumps({"cflib": metadata.version("cflib"), "python": "%d.%d.%d" % sys.version_info[:3],
                      "setpoints": setpoints, "seconds": t1 - t0,
                      "cpu_us": 1e6 * (cpu1 - cpu0) / setpoints if setpoints else None,
                      "packets_per_setpoint": (r1 - r0) / setpoints if setpoints else None}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
