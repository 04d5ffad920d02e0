"""WorldClock waits on the world's time, not the wall clock, and reports a stopped world."""
from __future__ import annotations

import time

import pytest

from crazyflie_driver.sim.world_clock import WorldClock, WorldStalled


class SlowWorld:
    """A world clock running at ``factor`` x real time from its creation."""

    def __init__(self, factor: float) -> None:
        self.factor, self.t0 = factor, time.monotonic()

    def __call__(self) -> float:
        return (time.monotonic() - self.t0) * self.factor


def test_sleep_lasts_world_seconds_on_a_slow_world():
    clock = WorldClock(SlowWorld(0.25), poll_s=0.002)
    t0 = time.monotonic()
    w0, w1 = clock.sleep(0.05)
    wall = time.monotonic() - t0
    assert w1 - w0 >= 0.05
    assert wall >= 0.05 / 0.25 * 0.95          # four times the wall time at a quarter of real time


def test_wait_until_returns_the_condition_and_the_world_time():
    world = SlowWorld(1.0)
    clock = WorldClock(world, poll_s=0.002)
    value, w = clock.wait_until(lambda: world() > 0.02 and "yes", 1.0)
    assert value == "yes"
    assert 0.02 <= w < 0.5
    value, w = clock.wait_until(lambda: False, 0.02)
    assert value is False


def test_a_stopped_world_is_an_error_not_an_endless_wait():
    clock = WorldClock(lambda: 12.5, poll_s=0.002, stall_s=0.05)
    with pytest.raises(WorldStalled, match="12.500"):
        clock.sleep(1.0)
