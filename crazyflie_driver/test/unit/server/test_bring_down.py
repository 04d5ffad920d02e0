"""The server's wait for landings before it closes links: on its clock, up to the budget, and not
past a clock that stands still."""
from __future__ import annotations

import logging

from crazyflie_driver.server.bring_down import CLOCK_STALL_S, POLL_S, bring_down


class StepClock:
    """A clock that moves ``step`` of its time per wait slice (0: it stands still)."""

    def __init__(self, step: float = POLL_S) -> None:
        self.t = 100.0
        self.step = step

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        self.t += seconds

    def wait(self, event, seconds: float) -> bool:
        self.t += seconds
        return event.is_set()

    def wall_bound(self, seconds: float) -> float:
        self.t += self.step
        return 0.0


class Worker:
    def __init__(self, uri: str, flying: bool, lands_after: float, clock: StepClock) -> None:
        self.uri = uri
        self.flying = flying
        self.lands_after = lands_after
        self.clock = clock
        self.started = None
        self.asked = []

    def begin_safe_shutdown(self, budget: float, why: str) -> bool:
        self.asked.append((budget, why))
        self.started = self.clock.now()
        return self.flying

    def safe_to_close(self) -> bool:
        return not self.flying or self.clock.now() - self.started >= self.lands_after


def test_nobody_in_the_air_means_no_wait():
    clock = StepClock()
    workers = [Worker("cf1", False, 0.0, clock), Worker("cf2", False, 0.0, clock)]
    assert bring_down(workers, "removed", 10.0, clock) == []
    assert clock.t == 100.0 and [w.asked for w in workers] == [[(10.0, "removed")]] * 2


def test_waits_on_its_clock_until_every_one_is_down(caplog):
    clock = StepClock()
    workers = [Worker("cf1", True, 1.0, clock), Worker("cf2", True, 2.5, clock), Worker("cf3", False, 0.0, clock)]
    with caplog.at_level(logging.WARNING, logger="crazyflie_driver.server"):
        assert bring_down(workers, "server shutting down", 10.0, clock) == []
    assert 2.5 <= clock.t - 100.0 < 2.5 + 2 * POLL_S
    assert "bringing down cf1, cf2 within 10.0 s" in caplog.text and "still descending" not in caplog.text


def test_a_landing_past_the_budget_is_named():
    clock = StepClock()
    workers = [Worker("cf1", True, 1.0, clock), Worker("cf2", True, 30.0, clock)]
    assert bring_down(workers, "removed", 7.0, clock) == ["cf2"]
    assert 7.0 <= clock.t - 100.0 < 7.0 + 2 * POLL_S


def test_a_clock_that_stands_still_ends_the_wait_after_its_wall_seconds(caplog):
    clock = StepClock(step=0.0)                 # the world is gone: /clock stopped
    wall = [0.0]

    def wall_now():
        wall[0] += 0.1
        return wall[0]
    with caplog.at_level(logging.ERROR, logger="crazyflie_driver.server"):
        assert bring_down([Worker("cf1", True, 1.0, clock)], "shutdown", 10.0, clock, wall=wall_now) == ["cf1"]
    assert CLOCK_STALL_S < wall[0] < CLOCK_STALL_S + 1.0
    assert "the clock stopped" in caplog.text
