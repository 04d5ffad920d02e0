"""The emergency-stop watchdog keep-alive of a swarm, by broadcast, without ROS.

Nothing in the firmware lands a Crazyflie that no longer hears its server: under the high-level
commander it flies on, and without motion capture it drifts away. The emergency-stop watchdog is
the one guard: once a Crazyflie has heard a keep-alive, one second without another stops its motors
until it is restarted. ``Heartbeat`` sends that keep-alive on every radio of the swarm, one packet per
radio per ``PERIOD_S`` whatever the number of Crazyflies (a unicast keep-alive each would cost a round
trip per Crazyflie), so a Crazyflie whose radio is unplugged or out of range stops within about a
second. What it costs and the consequences: the driver README, "Swarm mode".
"""
from __future__ import annotations

import logging
import threading
from typing import Callable, Optional

from crazyflie_driver.clock import WALL, Clock

LOG = logging.getLogger("crazyflie_driver.server.swarm")

#: s between two keep-alives: ten chances within the firmware's 1 s watchdog period. A broadcast has no
#: acknowledgement, so a lossy radio loses keep-alives outright: with 30 % packet loss all ten are lost with
#: probability 6e-6; with four (0.25 s) a Crazyflie on such a radio was stopped in the air within 1-2 s
#: (bench/bench_faults_swarm.py). Ten packets a second per radio.
PERIOD_S = 0.1


class Heartbeat:
    """Calls ``send()`` (the keep-alive on every radio; it raises when one failed, after trying all)
    every ``period_s`` of ``clock``'s time (the world's in a simulation, whose firmware counts its
    watchdog second on it) in a thread of its own until ``stop()``."""

    def __init__(self, send: Callable[[], object], period_s: float = PERIOD_S, clock: Clock = WALL) -> None:
        if period_s <= 0:
            raise ValueError("period_s must be > 0, got %r" % (period_s,))
        self._send = send
        self.period_s = period_s
        self._clock = clock
        self._stopped = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self.sent = 0
        self.errors = 0

    def start(self) -> Heartbeat:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="swarm heartbeat", daemon=True)
            self._thread.start()
        return self

    def stop(self, timeout: float = 1.0) -> None:
        """No keep-alive after this returns (every Crazyflie that heard one stops within a second)."""
        self._stopped.set()
        t = self._thread
        if t is not None and t is not threading.current_thread():
            t.join(timeout)

    @property
    def running(self) -> bool:
        return self._thread is not None and not self._stopped.is_set()

    def _run(self) -> None:
        while not self._stopped.is_set():
            try:
                self._send()
                self.sent += 1
            except Exception as e:      # a radio gone: the others still get theirs (send tries all)
                self.errors += 1
                if self.errors == 1 or self.errors % 100 == 0:
                    LOG.error("swarm: emergency-stop watchdog keep-alive failed (%d times so far): %s", self.errors, e)
            self._clock.wait(self._stopped, self.period_s)
