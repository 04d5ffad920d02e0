"""log: stream log variables to the terminal, one line per sample, for a number of seconds."""
from __future__ import annotations

import sys
from typing import List, Optional

from .common import listen_then_close, open_crazyflie, parser, run


def _log(args) -> int:
    names = [n for n in args.variables.split(",") if n]
    if args.seconds < 0:
        raise ValueError("--seconds must be >= 0, got %g" % args.seconds)
    cf = open_crazyflie(args)

    def show(timestamp_ms: int, values: List[float]) -> None:
        sys.stdout.write("%d %s\n" % (timestamp_ms, " ".join("%s=%.6g" % nv for nv in zip(names, values))))
        sys.stdout.flush()
    try:
        cf.log.create_block(names, args.period_ms, show)
    except BaseException:
        cf.close()
        raise
    listen_then_close(cf, args.seconds)
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    p = parser("Stream log variables of a Crazyflie to the terminal.")
    p.add_argument("--variables", required=True, help="comma-separated group.name, e.g. pm.vbat,stateEstimate.z")
    p.add_argument("--period-ms", type=int, default=100, help="sampling period (default %(default)s)")
    p.add_argument("--seconds", type=float, default=5.0, help="how long to stream (default %(default)s)")
    return run(_log, p.parse_args(argv), "log")


if __name__ == "__main__":
    sys.exit(main())
