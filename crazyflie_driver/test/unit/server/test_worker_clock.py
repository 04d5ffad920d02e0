"""The worker times everything on the clock it is given (the world's in a simulation), never on the wall clock.

Each test holds the clock still while wall time passes, then moves it: what the worker does must
follow the clock's seconds. These are also the pacing tests of the wall clock (the default): a count of
keepalives in a window of wall time measures how busy the machine is, not the worker.
"""
from __future__ import annotations

import threading
import time

import pytest

from crazyflie_driver.clock import ManualClock
from crazyflie_driver.server.swarm.estimator_placement import EstimatorPlacement
from crazyflie_driver.server.swarm.heartbeat import Heartbeat
from crazyflie_driver.server.worker import WorkerState
from support.worker_doubles import FakeCrazyflie, started, wait_for


def still_clock() -> ManualClock:
    return ManualClock(100.0, sleep_advances=False)


def test_keepalives_are_paced_in_the_clocks_seconds():
    clock = still_clock()
    w, cf, _ = started(clock=clock)
    try:
        time.sleep(0.05)
        n0 = len(cf.of_kind("null"))
        time.sleep(0.2)                     # 20 periods of wall time, none of the clock's
        assert len(cf.of_kind("null")) - n0 <= 1
        n1 = len(cf.of_kind("null"))
        for i in range(10):                 # ten periods of the clock, each given plenty of wall time
            clock.advance(0.010)
            assert wait_for(lambda: len(cf.of_kind("null")) >= n1 + i + 1, 1.0)
        time.sleep(0.05)
        assert 10 <= len(cf.of_kind("null")) - n1 <= 12
    finally:
        w.stop()


def test_link_lost_is_judged_on_the_clock():
    clock = still_clock()
    w, cf, rec = started(clock=clock, link_lost_timeout=1.0, lost_retry_period=0.1)
    try:
        cf.acking = False
        time.sleep(1.2)                     # longer than the timeout in wall time: not lost on the clock
        for _ in range(9):                  # 0.9 s of the clock, a round trip in each step
            n = len(cf.packets)
            clock.advance(0.1)
            assert wait_for(lambda: len(cf.packets) > n, 1.0)
        assert not rec.lost and w.state == WorkerState.RUNNING
        clock.advance(0.15)
        assert wait_for(lambda: rec.lost, 1.0)
        assert "no ack for 1.0 s" in rec.lost[0] or "no ack for 1.1 s" in rec.lost[0]
    finally:
        w.stop()


def test_the_connect_is_waited_for_in_the_clocks_seconds():
    clock = still_clock()
    cf = FakeCrazyflie(connect_delay=0.3)   # 0.3 s of wall time, no time of the clock
    w, cf, _ = started(cf=cf, clock=clock, ready_timeout=0.1)
    try:
        assert w.state == WorkerState.RUNNING
    finally:
        w.stop()


def test_a_connect_that_takes_longer_on_the_clock_times_out():
    clock = still_clock()
    cf = FakeCrazyflie(connect_delay=1.0)
    mover = threading.Timer(0.1, clock.advance, args=(0.5,))
    mover.start()
    t0 = time.monotonic()
    with pytest.raises(TimeoutError):
        started(cf=cf, clock=clock, ready_timeout=0.4)
    assert time.monotonic() - t0 < 0.9      # at the clock's 0.4 s, not after the connect's wall second
    mover.join()


def test_heartbeat_sends_once_per_period_of_its_clock():
    clock = still_clock()
    sent = []
    hb = Heartbeat(lambda: sent.append(clock.now()), period_s=0.25, clock=clock).start()
    try:
        assert wait_for(lambda: len(sent) == 1, 1.0)
        time.sleep(0.3)                     # more than a period of wall time
        assert len(sent) == 1
        for k in range(2, 5):
            clock.advance(0.25)
            assert wait_for(lambda: len(sent) == k, 1.0)
        assert sent == [100.0, 100.25, 100.5, 100.75]
    finally:
        hb.stop()


def test_estimator_placement_waits_the_clocks_seconds():
    clock = still_clock()
    p = EstimatorPlacement(clock)
    result = []
    waiter = threading.Thread(target=lambda: result.append(p.missing(["cf1", "cf2"], wait_s=5.0)))
    waiter.start()
    p.placed("cf1")
    time.sleep(0.2)
    assert waiter.is_alive()                # 0.2 s of wall time is nothing on this clock
    clock.advance(4.9)
    time.sleep(0.05)
    assert waiter.is_alive()
    clock.advance(0.2)
    waiter.join(1.0)
    assert result == [["cf2"]]
