"""Which Crazyflies of a swarm have their onboard estimator placed at their first motion-capture pose.

Until that parameter write is acknowledged, a Crazyflie's estimator believes it sits wherever it
booted (the origin, or its ``kalman.initial*``), and a takeoff plans from there: the Crazyflie would
fly from its real spot toward that point as the stream corrects the estimate, into its neighbours.
So a swarm takeoff waits a moment for the placements it needs and is refused for the rest.
"""
from __future__ import annotations

import threading
from typing import Iterable, List, Set

from crazyflie_driver.clock import WALL, Clock

#: How long a takeoff waits for the first fixes of the Crazyflies it addresses [s].
PLACEMENT_WAIT_S = 5.0


class EstimatorPlacement:
    """Thread-safe record of the Crazyflies placed (``placed``) and a bounded wait for some (``missing``),
    timed on ``clock``."""

    def __init__(self, clock: Clock = WALL) -> None:
        self._clock = clock
        self._placed: Set[str] = set()
        self._cond = threading.Condition()

    def placed(self, name: str) -> None:
        """``name``'s estimator was reset at its first pose (the write was acknowledged)."""
        with self._cond:
            self._placed.add(name)
            self._cond.notify_all()

    def is_placed(self, name: str) -> bool:
        with self._cond:
            return name in self._placed

    def missing(self, names: Iterable[str], wait_s: float = PLACEMENT_WAIT_S) -> List[str]:
        """Those of ``names`` still not placed after waiting up to ``wait_s`` for them (in their order)."""
        wanted = list(names)
        deadline = self._clock.now() + max(0.0, wait_s)
        with self._cond:
            while True:
                left = [n for n in wanted if n not in self._placed]
                remaining = deadline - self._clock.now()
                if not left or remaining <= 0:
                    return left
                self._cond.wait(self._clock.wall_bound(remaining))


def refusal(missing: List[str], wait_s: float = PLACEMENT_WAIT_S) -> str:
    """Why a takeoff is refused, with what to check."""
    return ("%s: no first motion-capture pose has placed the onboard estimator within %.0f s, and a takeoff "
            "now would fly from where the estimator believes the Crazyflie is, not from where it is. Check that "
            "motion capture sees it under its name (~mocap_pattern), then call takeoff again; nothing was sent"
            % (", ".join(missing), wait_s))
