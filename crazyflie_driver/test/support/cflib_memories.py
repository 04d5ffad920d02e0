#!/usr/bin/env python3
"""cflib's memory API against the simulated world, reported as JSON on stdout.

Run as ``cflib_session.py`` is (cflib's interpreter, ``crazyflie_driver/src`` and the test directory on
PYTHONPATH, CRAZYFLIE_SIM_ADDRESS naming the world server). Connects with SyncCrazyflie (whose connect
reads every one-wire memory), lists the memories, reads the EEPROM's configuration block with cflib's
I2CElement, writes a new channel and roll trim with it, and reads the block back.
"""
from __future__ import annotations

import argparse
import json
import sys
import threading


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--uri", required=True)
    p.add_argument("--channel", type=int, required=True, help="radio channel to write")
    p.add_argument("--roll-trim", type=float, default=0.0)
    args = p.parse_args()
    from support.cflib_session import install_fake_dongle
    install_fake_dongle(1)
    import cflib.crtp
    from cflib.crazyflie import Crazyflie
    from cflib.crazyflie.mem import MemoryElement
    from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
    cflib.crtp.init_drivers()
    out: dict = {}
    with SyncCrazyflie(args.uri, cf=Crazyflie()) as scf:
        mem = scf.cf.mem
        out["memories"] = [[m.id, m.type, m.size] for m in mem.mems]
        out["decks"] = [[m.vid, m.pid, m.elements.get("Board name"), m.elements.get("Board revision"), m.valid]
                        for m in mem.get_mems(MemoryElement.TYPE_1W)]
        eeprom = mem.get_mems(MemoryElement.TYPE_I2C)[0]

        def read() -> dict:
            done = threading.Event()
            eeprom.update(lambda _m: done.set())
            if not done.wait(10.0):
                raise TimeoutError("cflib read no configuration block")
            return dict(eeprom.elements, valid=eeprom.valid)
        out["before"] = read()
        eeprom.elements["radio_channel"] = args.channel
        eeprom.elements["roll_trim"] = args.roll_trim
        written = threading.Event()
        eeprom.write_data(lambda _m, _a: written.set())
        if not written.wait(10.0):
            raise TimeoutError("cflib wrote no configuration block")
        out["after"] = read()
    sys.stdout.write(json.dumps(out, sort_keys=True) + "\n")


if __name__ == "__main__":
    main()
