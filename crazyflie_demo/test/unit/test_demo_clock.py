"""The swarm demo's phases last their length on the clock it is given (the world's in a simulation)."""
from __future__ import annotations

import threading
import time

import pytest

from crazyflie_driver.clock import ManualClock

swarm_demo_node = pytest.importorskip("crazyflie_demo.swarm_demo_node")


def test_a_phase_pause_lasts_its_seconds_of_the_clock():
    clock = ManualClock(50.0)                       # sleeps advance it: no wall time passes
    t0 = time.monotonic()
    assert swarm_demo_node.pause(clock, 2.5) is True
    assert clock.now() == pytest.approx(52.5)
    assert time.monotonic() - t0 < 1.0
    assert all(s <= 0.1 + 1e-9 for s in clock.sleeps)   # looks at the shutdown flag every 0.1 s


def test_a_phase_pause_waits_for_a_clock_that_stands_still():
    clock = ManualClock(0.0, sleep_advances=False)
    done = []
    t = threading.Thread(target=lambda: done.append(swarm_demo_node.pause(clock, 1.0)), daemon=True)
    t.start()
    time.sleep(0.3)                                 # wall time passes, the world's does not
    assert not done
    clock.advance(1.0)
    t.join(1.0)
    assert done == [True]
