"""version: firmware version and serial of each Crazyradio; with --uri also the Crazyflie's."""
from __future__ import annotations

import sys
from typing import List, Optional

from crazyflie_driver import usb_choice
from crazyflie_driver.errors import RadioAccessDenied, RadioNotFound
from crazyflie_driver.radio.crazyradio import list_radios

from .common import UDEV_HINT, open_crazyflie, parser, run


def _version(args) -> int:
    radios = list_radios(usb_choice.get_backend())
    if not radios:
        raise RadioNotFound("no Crazyradio found (is it plugged in? if it is: %s)" % UDEV_HINT)
    for radio in radios:
        if radio.serial is None:
            raise RadioAccessDenied("Crazyradio %d: cannot read its serial number" % radio.index)
        print("Crazyradio %d: firmware %.2f, serial %s" % (radio.index, radio.version, radio.serial))
    if args.uri:
        cf = open_crazyflie(args)
        try:
            line = "%s: protocol version %d" % (cf.uri, cf.protocol_version)
            if cf.protocol_version >= 2:
                line += ", firmware %s" % cf.platform.firmware_version()
        finally:
            cf.close()
        print(line)
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    p = parser("Print the Crazyradio firmware version and serial number.", uri=False)
    p.add_argument("--uri", default=None,
                   help="also ask this Crazyflie for its protocol and firmware version")
    return run(_version, p.parse_args(argv), "version")


if __name__ == "__main__":
    sys.exit(main())
