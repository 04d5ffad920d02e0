"""getParam: print the value of one parameter."""
from __future__ import annotations

import sys
from typing import List, Optional

from crazyflie_driver.protocol.toc import check_toc_name

from .common import open_crazyflie, parser, run


def _get(args) -> int:
    check_toc_name(args.name, "parameter")      # a name no Crazyflie can have: said before connecting
    cf = open_crazyflie(args)
    try:
        value = cf.params.get(args.name)
    finally:
        cf.close()
    print(value)
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    p = parser("Read one parameter of a Crazyflie.")
    p.add_argument("--name", required=True, help="parameter as group.name, e.g. ring.effect")
    return run(_get, p.parse_args(argv), "getParam")


if __name__ == "__main__":
    sys.exit(main())
