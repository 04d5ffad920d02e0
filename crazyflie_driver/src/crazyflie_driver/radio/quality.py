"""Link quality of one Crazyflie: the share of round trips acked over a recent window.

Each Crazyflie gets its own count (the original server shared one between all of them), so a
warning names the Crazyflie whose link is poor. The thresholds say when to warn and when the
link counts as recovered.
"""
from __future__ import annotations

from collections import deque

LINK_QUALITY_WARNING = 0.7
LINK_QUALITY_RECOVERED = 0.8        # hysteresis: a link hovering at 0.7 warns every few s, not per packet
LINK_QUALITY_WINDOW = 100           # round trips
LINK_QUALITY_MIN_SAMPLES = 20       # no verdict on fewer round trips than this


class LinkQuality:
    """Acked / sent over the last ``window`` round trips of one Crazyflie."""

    def __init__(self, window: int = LINK_QUALITY_WINDOW) -> None:
        self._results: deque = deque(maxlen=window)
        self._acked = 0

    def record(self, acked: bool) -> None:
        if len(self._results) == self._results.maxlen and self._results[0]:
            self._acked -= 1
        self._results.append(bool(acked))
        if acked:
            self._acked += 1

    @property
    def samples(self) -> int:
        return len(self._results)

    @property
    def value(self) -> float:
        return self._acked / len(self._results) if self._results else 1.0
