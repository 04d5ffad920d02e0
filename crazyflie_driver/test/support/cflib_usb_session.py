"""Run by cflib's interpreter: cflib 0.1.34, unmodified, scans and connects usb://0, a simulated
Crazyflie on the fake USB cable (in this process), and prints what it read as JSON. Imports our
package and ``support`` from the PYTHONPATH of the sourced devel space, which it inherits."""
from __future__ import annotations

import json
import sys
import tempfile

from crazyflie_driver.sim.air.dongle_timing import DongleTiming
from crazyflie_driver.sim.air.fake_usb import FakeUsbBackend
from support.cflib_find_patch import install_find_patch
from support.radio_rig import RadioRig


def main() -> int:
    rig = RadioRig()
    rig.medium.plug_usb(rig.firmware)
    backend = FakeUsbBackend(rig.medium, dongles=1, timing=DongleTiming.instant(), usb_crazyflies=1)
    install_find_patch(backend)
    import cflib.crtp
    from cflib.crazyflie import Crazyflie
    from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
    cflib.crtp.init_drivers()
    found = [uri for uri, _ in cflib.crtp.scan_interfaces() if uri.startswith("usb://")]
    before = rig.medium.round_trips        # the scan also swept the radio's channels
    with tempfile.TemporaryDirectory() as cache:
        with SyncCrazyflie("usb://0", cf=Crazyflie(rw_cache=cache)) as scf:
            effect = scf.cf.param.get_value("ring.effect")
    print(json.dumps({"found": found, "ring.effect": effect, "radio_round_trips": rig.medium.round_trips - before,
                      "cable_out": backend.cables[0].bulk_out}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
