"""listLogVariables: every log variable of a Crazyflie as ``group.name (type)``."""
from __future__ import annotations

import sys
from typing import List, Optional

from .common import open_crazyflie, parser, run


def _list(args) -> int:
    cf = open_crazyflie(args)
    try:
        entries = cf.log.fetch_toc()
    finally:
        cf.close()
    for entry in entries:
        print("%s (%s)" % (entry.full_name, entry.ctype))
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    p = parser("List the log variables of a Crazyflie.")
    return run(_list, p.parse_args(argv), "listLogVariables")


if __name__ == "__main__":
    sys.exit(main())
