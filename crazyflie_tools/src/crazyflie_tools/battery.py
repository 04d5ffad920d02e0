"""battery: print the battery voltage (log variable pm.vbat) of a Crazyflie."""
from __future__ import annotations

import sys
import time
from typing import List, Optional

from crazyflie_driver.errors import LinkTimeout

from .common import open_crazyflie, parser, run

VBAT = "pm.vbat"
PERIOD_MS = 100


def _battery(args) -> int:
    cf = open_crazyflie(args)
    try:
        samples = []
        block = cf.log.create_block([VBAT], PERIOD_MS, lambda ts, values: samples.append(values[0]))
        wait = max(args.timeout, 3 * PERIOD_MS / 1000.0)
        deadline = time.monotonic() + wait      # wall clock: a tool without ROS, timed for the person waiting
        while not samples and time.monotonic() < deadline:
            cf.send_keepalive()
            time.sleep(0.002)
        block.delete()
        if not samples:
            raise LinkTimeout("%s: no %s log data within %.1f s" % (cf.uri, VBAT, wait))
    finally:
        cf.close()
    print("%.2f V" % samples[0])
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    p = parser("Print the battery voltage of a Crazyflie.")
    return run(_battery, p.parse_args(argv), "battery")


if __name__ == "__main__":
    sys.exit(main())
