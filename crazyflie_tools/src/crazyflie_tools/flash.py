"""flash: write a firmware image to a Crazyflie's STM32 or nRF51 through its bootloader, verify it by
reading it back, and boot the new firmware (docs/bootloader.md).

The Crazyflie is rebooted into its bootloader first (its radio chip takes that even with a hung flight
controller). A file that is obviously not a firmware for the chosen chip is refused before anything
is written.
"""
from __future__ import annotations

import sys
from typing import List, Optional

from crazyflie_driver import usb_choice
from crazyflie_driver.crtp import bootloader as bl
from crazyflie_driver.errors import FirmwareImageError, NotSupported
from crazyflie_driver.protocol import flasher
from crazyflie_driver.protocol.crazyflie import Crazyflie

from .common import parser, run

MODES = ("flashAndVerify", "flashOnly", "verifyOnly")


def _flash(args) -> int:
    try:
        with open(args.file, "rb") as f:
            image = f.read()
    except OSError as e:
        raise FirmwareImageError("cannot read %s: %s" % (args.file, e.strerror)) from None
    target = bl.TARGETS[args.target]
    cf = Crazyflie(args.uri, usb_choice.radio_manager(), timeout=args.timeout)
    exchange = getattr(cf.link, "exchange_raw", None)
    if exchange is None:
        raise NotSupported("%s: flashing needs a radio link (this link is %s)" % (cf.uri, type(cf.link).__name__))
    cf.link.open()
    try:
        if args.mode == "verifyOnly":
            info = flasher.verify_only(exchange, target, image)
            cf.close()
            print("%s: %s: the flash holds the image (%d bytes from page %d)"
                  % (cf.uri, args.target, len(image), info.start_page))
            return 0
        result = flasher.flash(exchange, target, image, verify_after=args.mode == "flashAndVerify")
    finally:
        cf.close()
    print("%s: %s: wrote %d bytes (%d pages from page %d)%s, rebooted into the firmware"
          % (cf.uri, args.target, result.bytes_written, result.pages_written, result.info.start_page,
             ", verified" if args.mode == "flashAndVerify" else ""))
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    p = parser("Flash a firmware image (.bin) to a Crazyflie's STM32 or nRF51 through its bootloader, "
               "verify it and boot it.")
    p.add_argument("--target", choices=sorted(bl.TARGETS), required=True, help="chip to flash")
    p.add_argument("--filename", "--file", dest="file", required=True, help="the firmware image (.bin) for that chip")
    p.add_argument("--mode", choices=MODES, default=MODES[0],
                   help="flashAndVerify (default), flashOnly (no read-back), verifyOnly (compare, write nothing)")
    return run(_flash, p.parse_args(argv), "flash")


if __name__ == "__main__":
    sys.exit(main())
