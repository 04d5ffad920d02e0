"""listParams: every parameter of a Crazyflie as ``group.name (type[, readonly])``."""
from __future__ import annotations

import sys
from typing import List, Optional

from .common import open_crazyflie, parser, run


def format_param(entry) -> str:
    return "%s (%s%s)" % (entry.full_name, entry.ctype, ", readonly" if entry.readonly else "")


def _list(args) -> int:
    cf = open_crazyflie(args)
    try:
        entries = cf.params.fetch_toc()
        values = cf.params.read_all() if args.values else {}
    finally:
        cf.close()
    for entry in entries:
        line = format_param(entry)
        if args.values:
            line += " = %s" % (values[entry.full_name],)
        print(line)
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    p = parser("List the parameters of a Crazyflie.")
    p.add_argument("--values", action="store_true", help="also read and print every value")
    return run(_list, p.parse_args(argv), "listParams")


if __name__ == "__main__":
    sys.exit(main())
