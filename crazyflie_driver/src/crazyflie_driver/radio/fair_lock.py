"""A first-in first-out lock, so that links sharing one Crazyradio get equal shares of its round trips,
with a guaranteed share of the dongle's time for plain turns when urgent bursts would take it all."""
from __future__ import annotations

import math
import threading
import time
from collections import deque
from typing import Any, Callable, Tuple

#: Time constant (s) of the decaying average that measures the capped turns' share of the dongle:
#: about ten motion-capture bursts at 100 Hz, short enough to react within a few frames.
SHARE_WINDOW_S = 0.2
#: Longest wait (s) of a background turn while plain ones keep coming: a keep-alive nobody waits for
#: still goes out at least this often, so the Crazyflie's transmit queue keeps draining.
BACKGROUND_MAX_WAIT_S = 0.2
#: Longest wait (s) of a plain turn while urgent ones keep coming: 8 Crazyflies streaming setpoints at
#: 100 Hz on one dongle ask for twice its round trips, and a worker whose poll waited behind them
#: forever sent none of its own setpoints either (5 round trips of a shared dongle, 2.3 ms each, are
#: about 12 ms; this is four times that).
PLAIN_MAX_WAIT_S = 0.05


class FairLock:
    """A FIFO lock: waiting threads get it in arrival order, so N Crazyflies polling flat out on
    one dongle each get 1/N of its round trips (``threading.Lock`` lets the releasing thread win).

    ``acquire(urgent=True)`` queues ahead of the plain waiters (behind earlier urgent ones): a
    setpoint then waits for the round trip in progress and the setpoints before it, not for
    every other Crazyflie's poll; a plain turn that has waited ``PLAIN_MAX_WAIT_S`` goes before the
    uncapped urgent ones all the same, so setpoints that ask for more than the dongle has cannot
    starve it.

    ``acquire(urgent=True, capped=True)`` (broadcast bursts) is urgent only while the capped turns
    have held the lock for less than ``capped_share`` of the recent time (a decaying average over
    ``SHARE_WINDOW_S``): past it, a waiting plain turn goes first, so unicast round trips (requests,
    keep-alives) keep at least ``1 - capped_share`` of the dongle however many bursts queue up.
    With no plain turn waiting the capped one goes at once: no dongle time is left unused.

    ``acquire(background=True)`` (keep-alive polls nobody waits for) goes after every plain waiter,
    unless it has waited ``BACKGROUND_MAX_WAIT_S``: requests waiting for an answer then get the
    unicast share instead of the Crazyflies' idle polls. It counts as unicast for the reserve.
    """

    __slots__ = ("_mutex", "_held", "_waiters", "_urgent", "_background", "capped_share", "_clock", "_granted_at",
                 "_holder_capped", "_capped_busy", "_busy_at", "capped_deferred")

    def __init__(self, capped_share: float = 1.0, clock: Callable[[], float] = time.monotonic) -> None:
        if not 0.0 < capped_share <= 1.0:
            raise ValueError("capped_share must be in (0, 1], got %r" % (capped_share,))
        self._mutex = threading.Lock()
        self._held = False
        self._waiters: deque = deque()
        self._urgent: deque = deque()          # (waiter, capped)
        self._background: deque = deque()      # (waiter, queued at)
        self.capped_share = capped_share
        # Shares of the dongle's busy time (held in turns of well under a millisecond): the wall clock by
        # default, which resolves them; a share is the same ratio on any clock that runs steadily.
        self._clock = clock
        self._granted_at = 0.0
        self._holder_capped = False
        self._capped_busy = 0.0                # capped turns' held time, exponentially weighted, as of _busy_at
        self._busy_at = clock()
        self.capped_deferred = 0               # times a capped turn let a plain one go first

    def acquire(self, blocking: bool = True, timeout: float = -1, urgent: bool = False, capped: bool = False,
                background: bool = False) -> bool:
        with self._mutex:
            if not self._held:
                if capped and urgent:
                    self._grant(True)
                else:                       # _grant(False), written out: every round trip comes here
                    self._held = True
                    self._holder_capped = False
                return True
            if not blocking:
                return False
            waiter = threading.Lock()
            waiter.acquire()
            entry: Tuple[Any, object]      # (waiter, capped) or (waiter, queued at)
            if urgent:
                queue, entry = self._urgent, (waiter, capped)
            elif background:
                queue, entry = self._background, (waiter, self._clock())
            else:
                queue, entry = self._waiters, (waiter, self._clock())
            queue.append(entry)
        if waiter.acquire(True, timeout):
            return True
        with self._mutex:
            try:
                queue.remove(entry)
            except ValueError:
                return True   # handed over to us while timing out
            return False

    def _grant(self, capped: bool) -> None:
        self._held = True
        self._holder_capped = capped
        if capped:                      # only a capped turn's length counts towards its share
            self._granted_at = self._clock()

    def capped_share_now(self) -> float:
        """The capped turns' recent share of the dongle's time (0..1, decaying average)."""
        with self._mutex:
            return self._share(self._clock())

    def _share(self, now: float) -> float:
        return self._capped_busy * math.exp(-max(0.0, now - self._busy_at) / SHARE_WINDOW_S) / SHARE_WINDOW_S

    def release(self) -> None:
        with self._mutex:
            if not self._held:
                raise RuntimeError("release of an unlocked FairLock")
            if not (self._holder_capped or self._urgent or self._background or self._waiters):
                self._held = False      # nobody waits and no share to account: no clock reading
                return
            now = self._clock()
            if self._holder_capped:
                held = max(0.0, now - self._granted_at)
                self._capped_busy = (self._share(now) + 1.0 - math.exp(-held / SHARE_WINDOW_S)) * SHARE_WINDOW_S
                self._busy_at = now
            entry = self._next_urgent(now)
            if entry is not None and not entry[1] and self._plain_overdue(now):
                entry = None                # capped turns have their share rule instead
            if entry is not None:
                self._urgent.remove(entry)
                self._grant(entry[1])
                entry[0].release()          # ownership passes directly
            elif self._background and (not self._waiters or now - self._background[0][1] >= BACKGROUND_MAX_WAIT_S):
                self._grant(False)
                self._background.popleft()[0].release()
            elif self._waiters:
                self._grant(False)
                self._waiters.popleft()[0].release()
            else:
                self._held = False

    def _plain_overdue(self, now: float) -> bool:
        return bool(self._waiters) and now - self._waiters[0][1] >= PLAIN_MAX_WAIT_S

    def _next_urgent(self, now: float):
        """The urgent waiter to go next: the first one, unless it is capped, over its share and a
        plain turn waits (then the first uncapped urgent one, if any)."""
        if not self._urgent:
            return None
        over = bool(self._waiters or self._background) and self._share(now) >= self.capped_share
        for entry in self._urgent:
            if not (entry[1] and over):
                return entry
        self.capped_deferred += 1
        return None

    def locked(self) -> bool:
        return self._held

    __enter__ = acquire

    def __exit__(self, *exc) -> None:
        self.release()
