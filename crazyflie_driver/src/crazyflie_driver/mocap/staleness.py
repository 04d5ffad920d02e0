"""Per-tracker age of the last pose, stale/fresh transitions and throttled warnings.

Mocap systems simply stop sending a body they cannot see, so "no pose for N ms" is the only
staleness signal. Times are in seconds of one monotonic clock chosen by the caller.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Dict, List, Optional


@dataclass
class TrackerAge:
    name: str
    age: float              # seconds since the last pose (inf: never seen)
    stale: bool
    count: int              # poses received
    rate: float             # poses per second over the last report interval


@dataclass
class StaleEvent:
    name: str
    kind: str               # "stale" (became or still is stale, warning due), or "fresh" (came back)
    age: float


class StalenessMonitor:
    """Thread safe: ``seen`` is called from the socket thread, ``check`` from a timer."""

    def __init__(self, timeout: float = 0.1, warn_period: float = 5.0) -> None:
        if timeout <= 0:
            raise ValueError("stale timeout must be > 0 s, got %r" % (timeout,))
        self.timeout = float(timeout)
        self.warn_period = float(warn_period)
        self._lock = threading.Lock()
        self._last: Dict[str, float] = {}
        self._count: Dict[str, int] = {}
        self._stale: Dict[str, bool] = {}
        self._next_warn: Dict[str, float] = {}
        self._rate_mark: Dict[str, tuple] = {}

    def watch(self, name: str) -> None:
        """Expect poses of ``name`` (a tracker named in the configuration but not seen yet)."""
        with self._lock:
            self._count.setdefault(name, 0)

    def seen(self, name: str, now: float) -> None:
        with self._lock:
            self._last[name] = now
            self._count[name] = self._count.get(name, 0) + 1

    def age(self, name: str, now: float) -> float:
        with self._lock:
            t = self._last.get(name)
        return float("inf") if t is None else max(0.0, now - t)

    def names(self) -> List[str]:
        with self._lock:
            return sorted(self._count)

    def check(self, now: float) -> List[StaleEvent]:
        """Events due now: a tracker turning stale (then every ``warn_period`` while it stays
        stale) and a stale tracker turning fresh. Trackers never seen are not reported here."""
        events: List[StaleEvent] = []
        with self._lock:
            for name, t in self._last.items():
                age = now - t
                was = self._stale.get(name, False)
                if age > self.timeout:
                    if not was or now >= self._next_warn.get(name, 0.0):
                        events.append(StaleEvent(name, "stale", age))
                        self._next_warn[name] = now + self.warn_period
                    self._stale[name] = True
                elif was:
                    self._stale[name] = False
                    events.append(StaleEvent(name, "fresh", age))
        return events

    def report(self, now: float) -> List[TrackerAge]:
        """Age, staleness and rate of every tracker known (seen or watched)."""
        out = []
        with self._lock:
            for name in sorted(self._count):
                t: Optional[float] = self._last.get(name)
                age = float("inf") if t is None else max(0.0, now - t)
                count = self._count[name]
                prev = self._rate_mark.get(name)
                rate = 0.0
                if prev is not None and now > prev[0]:
                    rate = (count - prev[1]) / (now - prev[0])
                self._rate_mark[name] = (now, count)
                out.append(TrackerAge(name, age, age > self.timeout, count, rate))
        return out
