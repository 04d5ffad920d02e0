"""Bringing Crazyflies down before the server closes their links (its shutdown, a removal).

Each one in the air starts its shutdown reaction (land or descend); the server waits, on its clock,
up to the longest of their shutdown budgets for all of them to be safe to close. A clock that stands
still (a simulated world shut down first stops publishing ``/clock``) ends the wait early: nothing
lands in a world that no longer steps.
"""
from __future__ import annotations

import logging
import time
from typing import Callable, List, Protocol, Sequence

from crazyflie_driver.clock import Clock

LOG = logging.getLogger("crazyflie_driver.server")

#: Wall seconds [s] the clock may stand still while the shutdown waits for landings.
CLOCK_STALL_S = 2.0
#: Clock seconds [s] between two looks at the landings.
POLL_S = 0.02


class Landing(Protocol):
    """What the wait needs of a worker."""

    @property
    def uri(self) -> str:
        ...

    def begin_safe_shutdown(self, budget: float, why: str) -> bool:
        """Start the shutdown reaction; whether it is in the air (so there is something to wait for)."""
        ...

    def safe_to_close(self) -> bool:
        ...


def bring_down(workers: Sequence[Landing], why: str, budget: float, clock: Clock,
               wall: Callable[[], float] = time.monotonic) -> List[str]:
    """Land or descend those of ``workers`` in the air and wait up to ``budget`` [s of ``clock``] for it
    (see the module); the URIs still descending when the wait ended."""
    flying = [w for w in workers if w.begin_safe_shutdown(budget, why)]
    if not flying:
        return []
    LOG.warning("crazyflie_server: %s: bringing down %s within %.1f s", why, ", ".join(w.uri for w in flying),
                budget)
    deadline = clock.now() + budget
    seen, moved_at = clock.now(), wall()
    while clock.now() < deadline and not all(w.safe_to_close() for w in flying):
        time.sleep(clock.wall_bound(POLL_S))     # a slice at most: a stopped clock must not block here
        if clock.now() != seen:
            seen, moved_at = clock.now(), wall()
        elif wall() - moved_at > CLOCK_STALL_S:
            LOG.error("crazyflie_server: the clock stopped for %.0f s (the simulated world is gone?): not "
                      "waiting for the landings any longer", CLOCK_STALL_S)
            break
    left = [w.uri for w in flying if not w.safe_to_close()]
    if left:
        LOG.error("crazyflie_server: %s still descending when the shutdown budget ran out", ", ".join(left))
    return left
