"""One warning per kind of refused input and second, not one per call site: a throttle keyed by
what was refused.

A topic handler that refuses a bad value says so in the log, throttled (a 100 Hz stream of NaN
must not flood it). Throttling by call site alone would let a refused ``cmd_position.x`` hide a
refused ``external_pose`` quaternion of another Crazyflie for a second; here the key is the
Crazyflie, the topic and the refusal's text with its numbers taken out (the field and the rule),
and the next line of a key says how many were left unsaid.
"""
from __future__ import annotations

import re
import threading
import time
from typing import Callable, Dict, Optional, Tuple

#: Numbers as the refusal messages print them (repr of floats and ints, nan, inf).
_NUMBER = re.compile(r"[-+]?(?:nan|inf|(?:\d+\.?\d*|\.\d+)(?:e[-+]?\d+)?)", re.IGNORECASE)


def refusal_kind(message: str) -> str:
    """The refusal without its values: ``"x must be finite, got nan"`` -> ``"x must be finite, got #"``."""
    return _NUMBER.sub("#", message)


class RefusalThrottle:
    """``say(where, topic, message)`` -> the message to log now, or None while that kind was said
    less than ``period`` s ago (counted, and the count goes with the next message)."""

    def __init__(self, period: float = 1.0, clock: Callable[[], float] = time.monotonic) -> None:
        self.period = period
        self._clock = clock         # the wall clock by default: how often a person reads the same refusal
        self._lock = threading.Lock()
        self._said: Dict[Tuple[str, ...], Tuple[float, int]] = {}    # key -> (said at, unsaid since)

    def say(self, where: str, topic: str, message: str) -> Optional[str]:
        key = (where, topic, refusal_kind(message))
        now = self._clock()
        with self._lock:
            said_at, unsaid = self._said.get(key, (-1e18, 0))
            if now - said_at < self.period:
                self._said[key] = (said_at, unsaid + 1)
                return None
            self._said[key] = (now, 0)
        more = " (and %d more like it since the last message)" % unsaid if unsaid else ""
        return message + more
