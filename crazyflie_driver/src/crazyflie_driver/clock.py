"""The one clock every timing decision of the stack reads: the wall clock on hardware, the world's in simulation.

A pacing loop, a timeout, a staleness check or a safety threshold asks a ``Clock`` for the time
and waits on it. On hardware that is ``WallClock`` (``time.monotonic``). In simulation the ROS
nodes pass a clock that follows ROS time, which follows the world's ``/clock``
(``nodes.ros_clock``), so a world slowed down by a busy machine slows every decision with it
instead of making the host side late in world time. Unit tests pass ``ManualClock``.

The rule for waiting: a clock's ``wait``/``sleep`` of ``s`` seconds returns when ``s`` seconds of
*its* time have passed (or the event is set). A clock that follows another (``FollowingClock``)
polls that time in wall-clock slices; ``max_speed`` bounds how fast the followed time may run
relative to the wall clock, so a slice never oversleeps a deadline.
"""
from __future__ import annotations

import threading
import time
from typing import Callable, List, Optional, Protocol, TypeVar

T = TypeVar("T")


class Clock(Protocol):
    """Seconds on one monotonic time line, and waits measured on it."""

    def now(self) -> float:
        """The time [s] (monotonic within a run; its origin means nothing)."""
        ...

    def sleep(self, seconds: float) -> None:
        """Return once ``seconds`` [s] of this clock's time have passed."""
        ...

    def wait(self, event: threading.Event, seconds: float) -> bool:
        """Until ``event`` is set or ``seconds`` [s] of this clock's time have passed; whether it was set."""
        ...

    def wall_bound(self, seconds: float) -> float:
        """Wall seconds [s] a ``Condition.wait`` may block without passing ``seconds`` of this clock's time.

        For loops that wait on their own condition variable and re-check ``now()`` when they wake.
        """
        ...


class WallClock:
    """The host's monotonic clock: what hardware runs on."""

    def now(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)

    def wait(self, event: threading.Event, seconds: float) -> bool:
        return event.wait(max(0.0, seconds))

    def wall_bound(self, seconds: float) -> float:
        return max(0.0, seconds)


WALL = WallClock()
"""The process-wide wall clock (stateless, so one instance serves every caller)."""

MIN_SLICE_S = 0.0005
"""Shortest wall-clock slice [s] a ``FollowingClock`` waits for at a time (bounds its polling cost)."""

MANUAL_POLL_S = 0.01
"""Wall seconds [s] a wait on a ``ManualClock`` blocks at a time before it looks at the time and its event again."""


class FollowingClock:
    """A clock that reads its time from ``now`` (e.g. ``rospy.get_time`` under ``/use_sim_time``).

    ``max_speed``: how many of its seconds may pass per wall second at most (1.0: the followed
    time never runs faster than real time, as a world slowed down for a busy machine). Waits
    sleep ``remaining / max_speed`` wall seconds at a time and re-read the time.
    ``stopped``: true once the followed time is heard no more (a ROS node shutting down); a wait
    then ends after what is left of it in wall seconds, so no loop hangs on a time that stands still.
    """

    def __init__(self, now: Callable[[], float], max_speed: float = 1.0,
                 stopped: Optional[Callable[[], bool]] = None) -> None:
        if not max_speed > 0:
            raise ValueError("max_speed must be > 0 (seconds of followed time per wall second), got %r"
                             % (max_speed,))
        self._now = now
        self.max_speed = float(max_speed)
        self._stopped = stopped if stopped is not None else (lambda: False)

    def now(self) -> float:
        return float(self._now())

    def wall_bound(self, seconds: float) -> float:
        return max(0.0, seconds) / self.max_speed

    def sleep(self, seconds: float) -> None:
        deadline = self.now() + seconds
        while True:
            left = deadline - self.now()
            if left <= 0:
                return
            if self._stopped():
                time.sleep(left / self.max_speed)
                return
            time.sleep(max(MIN_SLICE_S, left / self.max_speed))

    def wait(self, event: threading.Event, seconds: float) -> bool:
        deadline = self.now() + seconds
        while True:
            left = deadline - self.now()
            if left <= 0:
                return event.is_set()
            if self._stopped():
                return event.wait(left / self.max_speed)
            if event.wait(max(MIN_SLICE_S, left / self.max_speed)):
                return True


class ScaledClock:
    """A clock running at ``speed()`` × the wall clock: world time as a process without ``/clock`` sees it.

    ``speed``: the latest known world speed [world s per wall s] (e.g. what the world server's
    replies carry, ``RemoteMedium.speed``); read on every call, and a change starts a new segment so
    the time never jumps. At speed 1 it is ``time.monotonic`` itself and waits are wall waits, so a
    world at real time behaves exactly as before. Speed 0 (a world as fast as possible) waits nothing.
    """

    def __init__(self, speed: Callable[[], float]) -> None:
        self._speed = speed
        self._lock = threading.Lock()
        self._wall0 = time.monotonic()
        self._t0 = self._wall0
        self._s = 1.0

    def _current(self) -> float:
        s = max(0.0, float(self._speed()))
        if s != self._s:
            with self._lock:
                wall = time.monotonic()
                self._t0 += (wall - self._wall0) * self._s
                self._wall0, self._s = wall, s
        return s

    def now(self) -> float:
        s = self._current()
        with self._lock:
            return self._t0 + (time.monotonic() - self._wall0) * s

    def wall_bound(self, seconds: float) -> float:
        s = self._current()
        return max(0.0, seconds) / s if s > 0 else 0.0

    def sleep(self, seconds: float) -> None:
        wall = self.wall_bound(seconds)
        if wall > 0:
            time.sleep(wall)

    def wait(self, event: threading.Event, seconds: float) -> bool:
        return event.wait(self.wall_bound(seconds))


class ManualClock:
    """A clock for tests: time moves only by ``advance`` (or by ``sleep`` when ``sleep_advances``).

    ``wait`` and ``sleep`` block (when time does not move by themselves) until another thread's
    ``advance`` passes their deadline, so a test drives a threaded component tick by tick.
    """

    def __init__(self, start: float = 0.0, sleep_advances: bool = True) -> None:
        self._t = float(start)
        self._cond = threading.Condition()
        self.sleep_advances = sleep_advances
        self.sleeps: List[float] = []
        """Every ``sleep`` asked for [s], in order (what a test asserts pacing on)."""

    def now(self) -> float:
        with self._cond:
            return self._t

    def advance(self, seconds: float) -> float:
        """Move time on by ``seconds`` [s]; wakes waiters whose deadline passed. The new time."""
        if seconds < 0:
            raise ValueError("time does not go back: advance(%r)" % (seconds,))
        with self._cond:
            self._t += seconds
            self._cond.notify_all()
            return self._t

    def wall_bound(self, seconds: float) -> float:
        # Its time jumps when a test advances it: a waiter looks again within MANUAL_POLL_S.
        return min(max(0.0, seconds), MANUAL_POLL_S)

    def sleep(self, seconds: float) -> None:
        self.sleeps.append(seconds)
        if self.sleep_advances:
            self.advance(max(0.0, seconds))
            return
        self._block_until(self.now() + seconds, None)

    def wait(self, event: threading.Event, seconds: float) -> bool:
        if event.is_set():
            return True
        if self.sleep_advances:
            self.advance(max(0.0, seconds))
            return event.is_set()
        return self._block_until(self.now() + seconds, event)

    def _block_until(self, deadline: float, event: Optional[threading.Event]) -> bool:
        with self._cond:
            while self._t < deadline:
                if event is not None and event.is_set():
                    return True
                self._cond.wait(MANUAL_POLL_S)      # an event set by another thread is seen this soon
        return event.is_set() if event is not None else False


def wait_for(cond: Callable[[], T], seconds: float, now: Callable[[], float], period_s: float = 0.02,
             stop: Callable[[], bool] = lambda: False, wall: Callable[[], float] = time.monotonic,
             sleep: Callable[[float], None] = time.sleep) -> T:
    """``cond()``'s first truthy value, or its last one once ``seconds`` of ``now``'s time have passed.

    For a script or test that waits on a flight: with ``now`` = ROS time, a world that a busy machine
    slowed down is waited for as long as it takes in wall time. Where that time stands still (no
    ``/clock`` yet, or a world that is gone) the wait ends after ``seconds`` of wall time without
    progress instead of never. ``stop()`` (e.g. ``rospy.is_shutdown``) ends it at once.
    """
    t0, wall0 = now(), wall()
    last, last_move = t0, wall0
    while True:
        value = cond()
        if value or stop():
            return value
        t, w = now(), wall()
        if t != last:
            last, last_move = t, w
        if t - t0 >= seconds or w - last_move >= seconds:
            return value
        sleep(period_s)
