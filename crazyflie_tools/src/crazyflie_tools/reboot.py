"""reboot: restart a Crazyflie over the radio (into its firmware, or the bootloader), or switch it.

The Crazyflie's radio chip (nRF51) takes these commands itself, so they reach a Crazyflie whose flight
controller is locked, hung or switched off; only the link is opened, no connection is made.
"""
from __future__ import annotations

import sys
from typing import List, Optional

from crazyflie_driver import usb_choice
from crazyflie_driver.protocol.crazyflie import Crazyflie

from .common import parser, run

ACTIONS = {
    "firmware": ("reboot", "rebooted into its firmware"),
    "bootloader": ("reboot to the bootloader", "rebooted into the bootloader"),
    "stm-off": ("STM32 power off", "STM32 domain switched off (the radio stays on: --power stm-on)"),
    "stm-on": ("STM32 power on", "STM32 domain switched on (it boots)"),
    "all-off": ("power off", "switched off (only its power button switches it on again)"),
}


def _reboot(args) -> int:
    action = "bootloader" if args.bootloader else (args.power or "firmware")
    cf = Crazyflie(args.uri, usb_choice.radio_manager(), timeout=args.timeout)
    cf.link.open()
    try:
        if action in ("firmware", "bootloader"):
            cf.reboot(bootloader=action == "bootloader")
        elif action == "stm-off":
            cf.power_off_stm()
        elif action == "stm-on":
            cf.power_on_stm()
        else:
            cf.power_off_all()
    finally:
        cf.close()
    print("%s: %s" % (cf.uri, ACTIONS[action][1]))
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    p = parser("Reboot a Crazyflie over the radio (into its firmware unless told otherwise), or switch its "
               "power; its radio chip takes the command, so a locked or switched-off flight controller is "
               "reached too.")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--bootloader", action="store_true", help="reboot into the bootloader (to flash it)")
    group.add_argument("--power", choices=("stm-off", "stm-on", "all-off"), default=None,
                       help="instead of a reboot: switch the STM32 domain off or on, or everything off")
    return run(_reboot, p.parse_args(argv), "reboot")


if __name__ == "__main__":
    sys.exit(main())
