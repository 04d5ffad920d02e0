"""setParam: write one parameter (converted to its type) and print the value written."""
from __future__ import annotations

import sys
from typing import List, Optional

from crazyflie_driver.protocol.toc import check_toc_name

from .common import open_crazyflie, parser, run


def _set(args) -> int:
    check_toc_name(args.name, "parameter")      # a name no Crazyflie can have: said before connecting
    cf = open_crazyflie(args)
    try:
        written = cf.params.set(args.name, args.value)
    finally:
        cf.close()
    print("%s = %s" % (args.name, written))
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    p = parser("Write one parameter of a Crazyflie.")
    p.add_argument("--name", required=True, help="parameter as group.name, e.g. ring.effect")
    p.add_argument("--value", required=True, help="new value, converted to the parameter's type")
    return run(_set, p.parse_args(argv), "setParam")


if __name__ == "__main__":
    sys.exit(main())
