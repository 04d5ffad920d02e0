"""FairLock's capped turns: broadcast bursts go before waiting plain turns only within their share."""
from __future__ import annotations

import math
import threading
import time

import pytest

from crazyflie_driver.radio.fair_lock import BACKGROUND_MAX_WAIT_S, PLAIN_MAX_WAIT_S, SHARE_WINDOW_S, FairLock


class Clock:
    """A clock the lock's holders move on by the time their turn takes."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def queue_up(lock: FairLock, turns, clock: Clock, log):
    """Start one thread per (kind, seconds) in ``turns``, each queued before the next starts; each logs
    (kind, start, end) and moves the clock on by its seconds while it holds the lock."""
    threads = []
    for kind, seconds in turns:
        def turn(kind=kind, seconds=seconds):
            lock.acquire(urgent=kind in ("urgent", "capped"), capped=kind == "capped", background=kind == "idle")
            start = clock.t
            clock.t += seconds
            log.append((kind, start, clock.t))
            lock.release()
        t = threading.Thread(target=turn, daemon=True)
        queued = len(lock._waiters) + len(lock._urgent)
        t.start()
        deadline = time.monotonic() + 5.0
        while len(lock._waiters) + len(lock._urgent) == queued and time.monotonic() < deadline:
            time.sleep(0.0005)
        threads.append(t)
    return threads


def run(lock: FairLock, turns, clock: Clock):
    log = []
    lock.acquire()
    threads = queue_up(lock, turns, clock, log)
    lock.release()
    for t in threads:
        t.join(10.0)
    assert not lock.locked() and len(log) == len(turns)
    return log


def test_capped_turns_go_first_while_under_their_share():
    clock = Clock()
    lock = FairLock(capped_share=0.75, clock=clock)
    log = run(lock, [("plain", 0.002), ("capped", 0.010), ("capped", 0.010)], clock)
    assert [k for k, _, _ in log] == ["capped", "capped", "plain"]
    assert lock.capped_deferred == 0


def test_a_plain_turn_goes_first_once_the_capped_ones_had_their_share():
    clock = Clock()
    lock = FairLock(capped_share=0.75, clock=clock)
    lock.acquire(urgent=True, capped=True)       # a burst that held the dongle for two windows: 86 %
    clock.t += 2 * SHARE_WINDOW_S
    log = []
    threads = queue_up(lock, [("capped", 0.010), ("plain", 0.002), ("urgent", 0.001)], clock, log)
    lock.release()
    for t in threads:
        t.join(10.0)
    # the setpoint (urgent, not capped) still goes first; the burst waits for the poll
    assert [k for k, _, _ in log] == ["urgent", "plain", "capped"]
    assert lock.capped_deferred >= 1


def test_plain_turns_keep_their_reserve_under_a_flood_of_bursts():
    """17 Crazyflies' polls (2.3 ms each: bulk round trip + address switch) against motion-capture
    bursts of 13.2 ms queued back to back: the bursts get about ``capped_share`` of the time, the
    polls the rest, and neither is starved."""
    clock = Clock()
    lock = FairLock(capped_share=0.75, clock=clock)
    turns = [("capped", 0.0132)] * 60 + [("plain", 0.0023)] * 150
    log = run(lock, turns, clock)
    both_waiting_until = min(max(e for k, _, e in log if k == kind) for kind in ("capped", "plain"))
    span = [(k, s, e) for k, s, e in log if e <= both_waiting_until and s >= SHARE_WINDOW_S]
    capped = sum(e - s for k, s, e in span if k == "capped")
    total = span[-1][2] - span[0][1]
    assert capped / total == pytest.approx(0.75, abs=0.05)


def test_without_plain_waiters_a_capped_turn_never_waits():
    clock = Clock()
    lock = FairLock(capped_share=0.5, clock=clock)
    log = run(lock, [("capped", 0.2)] * 3, clock)
    assert [k for k, _, _ in log] == ["capped"] * 3 and lock.capped_deferred == 0
    assert lock.capped_share_now() == pytest.approx(1.0 - math.exp(-0.6 / SHARE_WINDOW_S))
    clock.t += SHARE_WINDOW_S
    assert lock.capped_share_now() == pytest.approx((1.0 - math.exp(-0.6 / SHARE_WINDOW_S)) * math.exp(-1.0))


def test_a_share_out_of_range_is_refused():
    with pytest.raises(ValueError, match="capped_share"):
        FairLock(capped_share=0.0)


def test_idle_polls_go_after_the_requests_unless_they_waited_too_long():
    clock = Clock()
    lock = FairLock(clock=clock)
    log = run(lock, [("idle", 0.002), ("plain", 0.002), ("plain", 0.002), ("urgent", 0.001)], clock)
    assert [k for k, _, _ in log] == ["urgent", "plain", "plain", "idle"]
    # requests queued back to back for longer than an idle poll may wait: it goes once it has waited that long
    clock = Clock()
    lock = FairLock(clock=clock)
    log = run(lock, [("idle", 0.002)] + [("plain", 0.05)] * 6, clock)
    kinds = [k for k, _, _ in log]
    idle_start = log[kinds.index("idle")][1]
    assert 0 < kinds.index("idle") < 6 and idle_start - 0.0 <= BACKGROUND_MAX_WAIT_S + 0.05


def test_idle_polls_count_as_unicast_for_the_reserve():
    clock = Clock()
    lock = FairLock(capped_share=0.75, clock=clock)
    lock.acquire(urgent=True, capped=True)
    clock.t += 2 * SHARE_WINDOW_S
    log = []
    threads = queue_up(lock, [("capped", 0.010), ("idle", 0.002)], clock, log)
    lock.release()
    for t in threads:
        t.join(10.0)
    assert [k for k, _, _ in log] == ["idle", "capped"]


def test_urgent_turns_cannot_starve_a_plain_one():
    """More urgent turns than the dongle carries (8 Crazyflies streaming setpoints at 100 Hz on one
    dongle): a waiting poll still goes once it has waited PLAIN_MAX_WAIT_S, not after all of them."""
    clock = Clock()
    lock = FairLock(clock=clock)
    log = run(lock, [("plain", 0.002)] + [("urgent", 0.010)] * 10, clock)
    kinds = [k for k, _, _ in log]
    plain_start = log[kinds.index("plain")][1]
    assert kinds.index("plain") < 10
    assert PLAIN_MAX_WAIT_S <= plain_start <= PLAIN_MAX_WAIT_S + 0.010
    # within the limit urgent turns still go first
    clock = Clock()
    lock = FairLock(clock=clock)
    log = run(lock, [("plain", 0.002)] + [("urgent", 0.010)] * 3, clock)
    assert [k for k, _, _ in log] == ["urgent"] * 3 + ["plain"]
