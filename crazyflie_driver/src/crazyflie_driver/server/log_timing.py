"""How old a Crazyflie's log data is when it arrives, and how much of it arrives.

Every log packet carries the Crazyflie's clock (u24 ms) at the moment the firmware sampled it.
:class:`OnboardClock` maps that clock to the host's: the offset host - onboard is the true offset
plus the packet's delay, so the smallest offset seen is the best estimate of the true one. A
packet's age is its offset minus that estimate. Between polls that find the Crazyflie's queue
empty (:meth:`OnboardClock.drained`: the last packet fetched was fresh, and its offset is taken
as the new estimate, which follows the clocks' drift and a simulated world that fell behind real
time) the estimate may rise by at most ``MAX_DRIFT`` s per s: a queue that stays full cannot
pull it up and hide its delay. :class:`TopicTiming` counts, per topic, the
packets that arrived per onboard second and the ones missing from the onboard timestamps (a gap
of several periods: the Crazyflie's transmit queue was full and dropped them).
"""
from __future__ import annotations

from collections import deque
from typing import Deque, Optional

ONBOARD_CLOCK_WRAP_MS = 1 << 24     # the log packets' timestamp is 24 bits of ms (wraps after 4.66 h)
MAX_DRIFT = 500e-6                  # s per s the onboard and host clocks may drift apart
REBOOT_JUMP_MS = 1000               # the onboard clock going back this far means the Crazyflie restarted
LATE_DATA_WARNING_S = 0.5           # log data older than this on arrival is reported as late
RATE_WINDOW_S = 2.0                 # s of host time the arrival rate is counted over


class OnboardClock:
    """Onboard ms -> age on arrival (s), for one Crazyflie."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self._offset: Optional[float] = None       # s, host - onboard, the lower envelope
        self._last_observed: Optional[float] = None
        self._last_host = 0.0
        self._last_raw: Optional[int] = None
        self._onboard_s = 0.0                       # unwrapped onboard time, s

    def onboard_seconds(self, raw_ms: int) -> float:
        """The unwrapped onboard time of a timestamp (feed timestamps in arrival order)."""
        if self._last_raw is not None:
            delta = (int(raw_ms) - self._last_raw) % ONBOARD_CLOCK_WRAP_MS
            if delta >= ONBOARD_CLOCK_WRAP_MS // 2:
                delta -= ONBOARD_CLOCK_WRAP_MS
            if delta < -REBOOT_JUMP_MS:
                self.reset()
                return self.onboard_seconds(raw_ms)
            self._onboard_s += delta / 1000.0
        else:
            self._onboard_s = int(raw_ms) / 1000.0
        self._last_raw = int(raw_ms)
        return self._onboard_s

    def age(self, onboard_s: float, host_s: float) -> float:
        """Seconds between the sampling of a packet (onboard time) and its arrival (host time)."""
        observed = host_s - onboard_s
        self._last_observed = observed
        if self._offset is None:
            self._offset = observed
        else:
            self._offset = min(self._offset + MAX_DRIFT * max(0.0, host_s - self._last_host), observed)
        self._last_host = host_s
        return observed - self._offset

    def drained(self) -> None:
        """A poll found the transmit queue empty: the last packet fetched left it at once."""
        if self._last_observed is not None:
            self._offset = self._last_observed


class TopicTiming:
    """One log topic: last age, packets arrived per second, packets the onboard timestamps say are missing."""

    def __init__(self, period_ms: int) -> None:
        self.period_s = max(period_ms, 1) / 1000.0
        self.count = 0
        self.lost = 0
        self.age = 0.0
        self._times: Deque[float] = deque()
        self._last: Optional[float] = None

    def record(self, onboard_s: float, age: float, host_s: float) -> None:
        self.count += 1
        self.age = age
        if self._last is not None:
            gap = onboard_s - self._last
            if gap > 1.5 * self.period_s:
                self.lost += int(round(gap / self.period_s)) - 1
        self._last = onboard_s
        self._times.append(host_s)
        while self._times and host_s - self._times[0] > RATE_WINDOW_S:
            self._times.popleft()

    @property
    def rate(self) -> float:
        """Packets that arrived per second, over the last ``RATE_WINDOW_S`` of arrivals."""
        if len(self._times) < 2:
            return 0.0
        span = self._times[-1] - self._times[0]
        return (len(self._times) - 1) / span if span > 0 else 0.0
