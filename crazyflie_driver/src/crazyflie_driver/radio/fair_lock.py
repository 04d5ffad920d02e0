"""A first-in first-out lock, so that links sharing one Crazyradio get equal shares of its round trips."""
from __future__ import annotations

import threading
from collections import deque


class FairLock:
    """A FIFO lock: waiting threads get it in arrival order, so N Crazyflies polling flat out on
    one dongle each get 1/N of its round trips (``threading.Lock`` lets the releasing thread win).

    ``acquire(urgent=True)`` queues ahead of the plain waiters (behind earlier urgent ones): a
    setpoint then waits for the round trip in progress and the setpoints before it, not for
    every other Crazyflie's poll.
    """

    __slots__ = ("_mutex", "_held", "_waiters", "_urgent")

    def __init__(self) -> None:
        self._mutex = threading.Lock()
        self._held = False
        self._waiters: deque = deque()
        self._urgent: deque = deque()

    def acquire(self, blocking: bool = True, timeout: float = -1, urgent: bool = False) -> bool:
        with self._mutex:
            if not self._held:
                self._held = True
                return True
            if not blocking:
                return False
            waiter = threading.Lock()
            waiter.acquire()
            queue = self._urgent if urgent else self._waiters
            queue.append(waiter)
        if waiter.acquire(True, timeout):
            return True
        with self._mutex:
            try:
                queue.remove(waiter)
            except ValueError:
                return True   # handed over to us while timing out
            return False

    def release(self) -> None:
        with self._mutex:
            if self._urgent:
                self._urgent.popleft().release()    # ownership passes directly
            elif self._waiters:
                self._waiters.popleft().release()
            elif self._held:
                self._held = False
            else:
                raise RuntimeError("release of an unlocked FairLock")

    def locked(self) -> bool:
        return self._held

    __enter__ = acquire

    def __exit__(self, *exc) -> None:
        self.release()
