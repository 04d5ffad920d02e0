"""Swarm files for the swarm demo: n Crazyflies in a square grid, spread over up to three channels.

``swarm_file_text(49)`` is ``crazyflie_demo/config/swarm49.yaml``: a 7 × 7 grid, 0.5 m apart,
centred on the origin, ids 1..49 row by row, channels 80/90/100 in contiguous blocks (17/16/16),
so the server gives each channel its own Crazyradio. The type flies as Crazyswarm does: the
Kalman estimator (it fuses the motion capture) and the Mellinger controller (it tracks a
trajectory's velocity and acceleration, not only its position). Regenerate a shipped file with
``rosrun crazyflie_demo swarm_grid N > crazyflie_demo/config/swarmN.yaml``.
"""
from __future__ import annotations

import math
import sys
from typing import List, Optional, Sequence, Tuple

SPACING_M = 0.5
CHANNELS = (80, 90, 100)
#: The grid sizes shipped in crazyflie_demo/config (swarm.launch's n).
SHIPPED = (1, 4, 9, 16, 25, 49)


def grid_positions(n: int, spacing: float = SPACING_M) -> List[Tuple[float, float]]:
    """n (x, y) positions row by row on the smallest square grid that holds them, centred on the origin."""
    if n < 1:
        raise ValueError("a swarm needs at least one Crazyflie, got %d" % n)
    side = math.ceil(math.sqrt(n))
    offset = (side - 1) * spacing / 2.0
    return [((i % side) * spacing - offset, (i // side) * spacing - offset) for i in range(n)]


def channel_blocks(n: int, channels: Sequence[int] = CHANNELS) -> List[int]:
    """The channel of each of n Crazyflies: contiguous blocks, the first ones one larger (49: 17/16/16)."""
    k = min(n, len(channels))
    sizes = [n // k + (1 if i < n % k else 0) for i in range(k)]
    return [channels[i] for i, size in enumerate(sizes) for _ in range(size)]


def swarm_file_text(n: int, spacing: float = SPACING_M, channels: Sequence[int] = CHANNELS) -> str:
    positions = grid_positions(n, spacing)
    chans = channel_blocks(n, channels)
    side = math.ceil(math.sqrt(n))
    per = ", ".join("%d on %d" % (chans.count(c), c) for c in sorted(set(chans)))
    lines = ["# %d simulated or real Crazyflie%s in a %d x %d grid, %.2f m apart, centred on the origin;"
             % (n, "" if n == 1 else "s", side, side, spacing),
             "# channels: %s (one Crazyradio per channel)." % per,
             "# Written by: rosrun crazyflie_demo swarm_grid %d" % n,
             "crazyflies:"]
    for i, ((x, y), ch) in enumerate(zip(positions, chans)):
        lines.append("  - {id: %d, channel: %d, initialPosition: [%.2f, %.2f, 0.0], type: default}" % (i + 1, ch, x, y))
    lines += ["crazyflieTypes:",
              "  default:",
              "    firmwareParams:",
              "      commander: {enHighLevel: 1}",
              "      stabilizer: {estimator: 2, controller: 2}    # Kalman (takes motion capture), Mellinger",
              "    batteryVoltageWarning: 3.8",
              "    batteryVoltageCritical: 3.7",
              ""]
    return "\n".join(lines)


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    try:
        n = int(args[0]) if args else 49
        sys.stdout.write(swarm_file_text(n))
    except ValueError as e:
        print("swarm_grid: %s (usage: swarm_grid N, N >= 1)" % e, file=sys.stderr)
        return 2
    return 0
