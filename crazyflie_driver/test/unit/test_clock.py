"""The clocks timing decisions read: wall, following (ROS/world time) and manual (tests)."""
from __future__ import annotations

import threading
import time

import pytest

from crazyflie_driver.clock import WALL, FollowingClock, ManualClock, wait_for


def test_wall_clock_is_monotonic_and_waits_on_events():
    t0 = WALL.now()
    ev = threading.Event()
    ev.set()
    assert WALL.wait(ev, 5.0) is True
    assert WALL.now() >= t0


def test_following_clock_sleeps_until_the_followed_time_passes():
    """A followed time running at a quarter of real time: a 0.05 s sleep lasts about 0.2 wall seconds."""
    w0 = time.monotonic()
    clock = FollowingClock(lambda: (time.monotonic() - w0) * 0.25)
    t0 = clock.now()
    clock.sleep(0.05)
    assert clock.now() - t0 >= 0.05
    assert time.monotonic() - w0 >= 0.19


def test_following_clock_wait_returns_at_once_when_the_event_is_set():
    stopped = [0.0]
    clock = FollowingClock(lambda: stopped[0])          # a followed time that does not move
    ev = threading.Event()
    threading.Timer(0.05, ev.set).start()
    assert clock.wait(ev, 1.0) is True


def test_following_clock_wait_times_out_on_followed_time():
    t = [0.0]
    clock = FollowingClock(lambda: t[0])
    ev = threading.Event()

    def run():
        for _ in range(20):
            time.sleep(0.005)
            t[0] += 0.1
    threading.Thread(target=run, daemon=True).start()
    assert clock.wait(ev, 1.0) is False
    assert clock.now() >= 1.0


def test_following_clock_refuses_a_speed_that_is_not_positive():
    with pytest.raises(ValueError, match="max_speed"):
        FollowingClock(lambda: 0.0, max_speed=0.0)


def test_following_clock_waits_out_on_the_wall_clock_once_its_time_is_heard_no_more():
    """A node shutting down hears no /clock: a sleep or wait ends after its wall seconds, never hangs."""
    shut = threading.Event()
    clock = FollowingClock(lambda: 7.0, stopped=shut.is_set)     # the followed time stands still
    ev = threading.Event()
    threading.Timer(0.05, shut.set).start()
    t0 = time.monotonic()
    assert clock.wait(ev, 0.2) is False
    clock.sleep(0.2)
    assert 0.35 <= time.monotonic() - t0 < 1.0                  # each wait its 0.2 s, not forever


def test_manual_clock_waiters_on_their_own_condition_look_again_within_a_slice():
    clock = ManualClock()
    assert clock.wall_bound(5.0) <= 0.01 and clock.wall_bound(-1.0) == 0.0


def test_manual_clock_sleep_advances_and_records():
    clock = ManualClock(start=10.0)
    clock.sleep(0.25)
    clock.sleep(0.5)
    assert clock.now() == pytest.approx(10.75)
    assert clock.sleeps == [0.25, 0.5]


def test_manual_clock_blocks_waiters_until_advanced():
    clock = ManualClock(sleep_advances=False)
    ev = threading.Event()
    result = []
    th = threading.Thread(target=lambda: result.append(clock.wait(ev, 1.0)))
    th.start()
    clock.advance(0.5)
    th.join(0.1)
    assert th.is_alive()                         # half the timeout: still waiting
    clock.advance(0.6)
    th.join(2.0)
    assert result == [False]


def test_manual_clock_refuses_to_go_back():
    with pytest.raises(ValueError, match="does not go back"):
        ManualClock().advance(-1.0)


def test_scaled_clock_at_speed_one_is_the_wall_clock():
    from crazyflie_driver.clock import ScaledClock
    clock = ScaledClock(lambda: 1.0)
    a, t, b = time.monotonic(), clock.now(), time.monotonic()
    assert a <= t <= b
    assert clock.wall_bound(0.25) == 0.25


def test_scaled_clock_runs_at_the_speed_it_is_given_and_never_jumps():
    from crazyflie_driver.clock import ScaledClock
    speed = [0.5]
    clock = ScaledClock(lambda: speed[0])
    assert clock.wall_bound(0.01) == pytest.approx(0.02)
    t0, w0 = clock.now(), time.monotonic()
    clock.sleep(0.02)                                   # 0.02 s at half speed: 0.04 wall seconds
    assert time.monotonic() - w0 >= 0.039
    assert clock.now() - t0 == pytest.approx((time.monotonic() - w0) * 0.5, abs=0.005)
    before = clock.now()
    speed[0] = 2.0                                      # a new speed continues from where it was
    assert clock.now() == pytest.approx(before, abs=0.002)
    speed[0] = 0.0                                      # a world as fast as possible: no wall waits
    w1 = time.monotonic()
    clock.sleep(5.0)
    assert clock.wait(threading.Event(), 5.0) is False
    assert time.monotonic() - w1 < 0.1


class _Times:
    """A followed time and a wall clock that the test moves: each sleep advances the wall by its
    length and the followed time by ``rate`` times that."""

    def __init__(self, rate: float) -> None:
        self.rate, self.t, self.w, self.calls = rate, 0.0, 0.0, 0

    def sleep(self, s: float) -> None:
        self.w += s
        self.t += self.rate * s


def test_wait_for_measures_the_followed_time_so_a_slow_world_is_waited_for_longer_in_wall_time():
    slow = _Times(rate=0.1)              # the world at a tenth of real time
    assert wait_for(lambda: slow.t >= 1.5, 2.0, lambda: slow.t, 0.01, wall=lambda: slow.w, sleep=slow.sleep)
    assert 14.9 < slow.w < 15.2          # 1.5 world s took 15 wall s, within a 2 s (world) timeout
    slow = _Times(rate=0.1)
    assert wait_for(lambda: False, 2.0, lambda: slow.t, 0.01, wall=lambda: slow.w, sleep=slow.sleep) is False
    assert slow.t == pytest.approx(2.0, abs=0.002)


def test_wait_for_ends_after_its_length_in_wall_time_when_the_followed_time_stands_still():
    stopped = _Times(rate=0.0)           # no /clock yet, or a world that is gone
    assert wait_for(lambda: 0, 3.0, lambda: stopped.t, 0.01, wall=lambda: stopped.w, sleep=stopped.sleep) == 0
    assert stopped.w == pytest.approx(3.0, abs=0.02)
    assert wait_for(lambda: False, 3.0, lambda: 0.0, stop=lambda: True) is False     # shut down: at once
