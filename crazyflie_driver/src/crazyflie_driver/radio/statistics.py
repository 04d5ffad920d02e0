"""How well the radio link to one Crazyflie works: one window over its recent round trips.

Every radio packet of a link is counted (safelink re-sends included, which ``send``'s result hides),
per Crazyflie, so a warning names the Crazyflie whose link is poor. The thresholds say when the
server warns and when the link counts as recovered.
"""
from __future__ import annotations

from typing import Optional

STATS_WINDOW = 100                  # round trips
DEFAULT_LOST_THRESHOLD = 100        # unacked round trips in a row
LINK_QUALITY_WARNING = 0.7          # ack ratio below this: warn
LINK_QUALITY_RECOVERED = 0.8        # hysteresis: a link hovering at 0.7 warns every few s, not per packet
LINK_QUALITY_MIN_SAMPLES = 20       # no verdict on fewer round trips than this


class LinkStatistics:
    """Per-Crazyflie counters, updated on every round trip.

    ``ack_ratio`` and ``retries`` (mean retransmissions of acked packets) cover the last ``window``
    round trips (``samples`` of them so far); ``rssi`` is the latest value carried by an empty ack
    (raw, i.e. -dBm), None until one arrives; ``link_lost`` is true after ``lost_threshold`` unacked
    round trips in a row. ``sent``, ``acked``, ``retries_total`` and ``busy_s`` (seconds spent in
    round trips, waiting for the shared dongle included) only grow: ``/diagnostics`` turns their
    differences over a time window into rates, ratios and the mean round-trip time.
    """

    def __init__(self, lost_threshold: int = DEFAULT_LOST_THRESHOLD, window: int = STATS_WINDOW):
        if window < 1 or lost_threshold < 1:
            raise ValueError("window and lost_threshold must be >= 1")
        self.lost_threshold = lost_threshold
        self.window = window
        self.sent = 0
        self.acked = 0
        self.retries_total = 0
        self.busy_s = 0.0
        self.consecutive_failures = 0
        self.rssi: Optional[int] = None
        self._acks = [0] * window
        self._retries = [0] * window
        self._pos = 0
        self._filled = 0
        self._ack_sum = 0
        self._retry_sum = 0

    def record(self, acked: bool, retries: int = 0, seconds: float = 0.0) -> None:
        """One round trip: acked or not, after ``retries`` retransmissions by the dongle, ``seconds`` long."""
        pos = self._pos
        a = 1 if acked else 0
        r = retries if acked else 0
        self._ack_sum += a - self._acks[pos]
        self._retry_sum += r - self._retries[pos]
        self._acks[pos] = a
        self._retries[pos] = r
        pos += 1
        self._pos = 0 if pos == self.window else pos
        if self._filled < self.window:
            self._filled += 1
        self.sent += 1
        self.busy_s += seconds
        if acked:
            self.acked += 1
            self.retries_total += r
            self.consecutive_failures = 0
        else:
            self.consecutive_failures += 1

    @property
    def samples(self) -> int:
        """Round trips in the window so far (at most ``window``)."""
        return self._filled

    @property
    def ack_ratio(self) -> float:
        """Acked fraction of the last ``window`` round trips (0.0 before the first one)."""
        return self._ack_sum / self._filled if self._filled else 0.0

    @property
    def retries(self) -> float:
        """Mean retransmissions per acked packet over the window."""
        return self._retry_sum / self._ack_sum if self._ack_sum else 0.0

    @property
    def link_lost(self) -> bool:
        return self.consecutive_failures >= self.lost_threshold

    def as_dict(self) -> dict:
        return {"sent": self.sent, "acked": self.acked, "retries_total": self.retries_total,
                "busy_s": self.busy_s, "ack_ratio": self.ack_ratio,
                "retries": self.retries, "rssi": self.rssi,
                "consecutive_failures": self.consecutive_failures, "link_lost": self.link_lost}

    def __repr__(self) -> str:
        return ("LinkStatistics(sent=%d, acked=%d, ack_ratio=%.2f, retries=%.2f, rssi=%s, "
                "consecutive_failures=%d)" % (self.sent, self.acked, self.ack_ratio, self.retries,
                                              self.rssi, self.consecutive_failures))
