"""comCheck: link quality and round trips, measured with numbered echo packets (port 15)."""
from __future__ import annotations

import sys
from typing import List, Optional

from crazyflie_driver.protocol.echo import echo_round_trips, summarize

from .common import open_crazyflie, parser, run


def _check(args) -> int:
    if args.count < 1:
        raise ValueError("--count must be >= 1, got %d" % args.count)
    cf = open_crazyflie(args)
    try:
        trips = echo_round_trips(cf.link.request, args.count, args.size, args.timeout)
        stats = getattr(cf.link, "stats", None)
    finally:
        cf.close()
    s = summarize(trips)
    print("echo: %d sent, %d answered, %d lost (%.1f %%)" % (s.sent, s.answered, s.lost, 100.0 * s.lost / s.sent))
    if s.answered:
        print("round trip: min %.2f ms, mean %.2f ms, max %.2f ms" % (1e3 * s.min_s, 1e3 * s.mean_s, 1e3 * s.max_s))
    if stats is not None and stats.sent:
        print("radio: %d packets, %.1f %% acked, %.2f retries per packet"
              % (stats.sent, 100.0 * stats.acked / stats.sent, stats.retries_total / stats.sent))
    return 0 if s.answered else 1


def main(argv: Optional[List[str]] = None) -> int:
    p = parser("Check the link to a Crazyflie: echo round trips and packet loss.")
    p.add_argument("--count", type=int, default=100, help="echo packets to send (default %(default)s)")
    p.add_argument("--size", type=int, default=4, help="bytes per echo packet, 4..30 (default %(default)s)")
    return run(_check, p.parse_args(argv), "comCheck")


if __name__ == "__main__":
    sys.exit(main())
