"""console: print what the Crazyflie's firmware prints, for a number of seconds."""
from __future__ import annotations

import sys
from typing import List, Optional

from crazyflie_driver import usb_choice
from crazyflie_driver.protocol.crazyflie import Crazyflie

from .common import listen_then_close, parser, run


def _write(text: str) -> None:
    sys.stdout.write(text)
    sys.stdout.flush()


def _console(args) -> int:
    if args.seconds < 0:
        raise ValueError("--seconds must be >= 0, got %g" % args.seconds)
    cf = Crazyflie(args.uri, usb_choice.radio_manager(), timeout=args.timeout)
    cf.console.on_text(_write)   # before connect: the boot text arrives right away
    cf.connect()
    listen_then_close(cf, args.seconds)
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    p = parser("Print the console text of a Crazyflie.")
    p.add_argument("--seconds", type=float, default=5.0,
                   help="how long to listen (default %(default)s)")
    return run(_console, p.parse_args(argv), "console")


if __name__ == "__main__":
    sys.exit(main())
