"""Waiting on the simulated world's clock rather than the wall clock.

The firmware's timers (log blocks, watchdog) and the physics run on world time. On a busy
machine the world may fall behind real time; a test or benchmark that waits "2 s" on the wall
clock then sees less than 2 s of flight and fewer log packets, and judges the load instead of
the stack. Waiting for world seconds asks for what the firmware and the physics actually did.
"""
from __future__ import annotations

import time
from typing import Any, Callable, Optional, Tuple

POLL_S = 0.01            # how often the world's time is read while waiting (wall seconds)
STALL_S = 10.0           # wall seconds without any world progress before a wait gives up


class WorldStalled(TimeoutError):
    """The world's time did not move for STALL_S wall seconds (the world is stopped or gone)."""


class WorldClock:
    """The world's time through ``now()`` (e.g. ``RemoteMedium.ping``), and waits measured on it."""

    def __init__(self, now: Callable[[], float], poll_s: float = POLL_S, stall_s: float = STALL_S) -> None:
        self._now = now
        self.poll_s = poll_s
        self.stall_s = stall_s

    def now(self) -> float:
        """World time in seconds."""
        return float(self._now())

    def sleep(self, seconds: float) -> Tuple[float, float]:
        """Until ``seconds`` of world time have passed; the (start, end) world times."""
        w0 = self.now()
        w1 = self.wait_until(lambda: False, seconds, start=w0)[1]
        return w0, w1

    def wait_until(self, cond: Callable[[], Any], seconds: float,
                   start: Optional[float] = None) -> Tuple[Any, float]:
        """cond()'s first truthy value within ``seconds`` of world time (else its last), and the world time then.

        Raises WorldStalled when the world's time stops moving, so a dead world is an error and
        not an endless wait.
        """
        w0 = self.now() if start is None else start
        last_w, last_move = w0, time.monotonic()
        while True:
            v = cond()
            w = self.now()
            if v or w - w0 >= seconds:
                return v, w
            if w > last_w:
                last_w, last_move = w, time.monotonic()
            elif time.monotonic() - last_move > self.stall_s:
                raise WorldStalled("the simulated world's time stayed at %.3f s for %.0f s of wall time; "
                                   "is the world (crazyflie_sim) still running?" % (w, self.stall_s))
            time.sleep(self.poll_s)
