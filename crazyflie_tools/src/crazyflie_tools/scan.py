"""scan: the dongle's version line, then every Crazyflie that answers on any data rate and channel at one address,
then every Crazyflie on a USB cable (usb://N)."""
from __future__ import annotations

import sys
from typing import List, Optional

from crazyflie_driver import usb_choice
from crazyflie_driver.crtp.uri import DEFAULT_ADDRESS, RadioUri
from crazyflie_driver.radio.crazyradio import Crazyradio
from crazyflie_driver.radio.scan import parse_address, scan
from crazyflie_driver.radio.usb_crazyflie import list_usb_crazyflies

from .common import parser, run


def dongle_line(version: float) -> str:
    """The first line of the output, as the chapter shows it: the dongle's firmware version."""
    return "Configured Dongle with version %g" % version


def uri_line(uri: RadioUri) -> str:
    """The URI as the chapter's scan prints it: the address only when it is not the default one."""
    text = str(uri)
    return text.rsplit("/", 1)[0] if uri.address == DEFAULT_ADDRESS else text


def _scan(args) -> int:
    address = parse_address(args.address)
    backend = usb_choice.get_backend()
    radio = Crazyradio(args.radio, backend)
    try:
        print(dongle_line(radio.version), flush=True)
        found = scan(args.radio, address, radio=radio)
    finally:
        radio.close()
    for uri in found:
        print(uri_line(uri))
    cabled = list_usb_crazyflies(backend)
    for info in cabled:
        print(info.uri)
    if not found and not cabled:
        print("no Crazyflie answered at address %s" % address.hex().upper(), file=sys.stderr)
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    p = parser("Find Crazyflies: a null packet on every data rate and channel 0-125.", uri=False)
    p.add_argument("--address", default="E7E7E7E7E7",
                   help="radio address, up to 10 hex digits (default %(default)s)")
    p.add_argument("--radio", type=int, default=0, help="Crazyradio index (default 0)")
    return run(_scan, p.parse_args(argv), "scan")


if __name__ == "__main__":
    sys.exit(main())
