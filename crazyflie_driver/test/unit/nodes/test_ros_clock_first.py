"""ros_clock waits for the first /clock: no timeout is computed from time 0, and none at all is a clear error."""
from __future__ import annotations

import threading
import time

import pytest

rospy = pytest.importorskip("rospy")

from crazyflie_driver.clock import FollowingClock  # noqa: E402
from crazyflie_driver.nodes import ros_clock as rc  # noqa: E402


def fake_ros(monkeypatch, sim_time: bool, ros_time):
    monkeypatch.setattr(rc.rospy, "get_param", lambda name, default=None: sim_time if name == "/use_sim_time"
                        else default)
    monkeypatch.setattr(rc.rospy, "get_time", lambda: ros_time[0])
    monkeypatch.setattr(rc.rospy, "is_shutdown", lambda: False)


def test_under_use_sim_time_it_follows_ros_time_once_the_first_clock_came(monkeypatch):
    t = [0.0]
    fake_ros(monkeypatch, True, t)
    threading.Timer(0.1, lambda: t.__setitem__(0, 40.0)).start()     # the world's first /clock
    t0 = time.monotonic()
    clock = rc.ros_clock()
    assert time.monotonic() - t0 >= 0.09                              # no timeout computed from time 0
    assert isinstance(clock, FollowingClock) and clock.now() == 40.0
    t[0] = 41.5
    assert clock.now() == 41.5


def test_no_clock_at_all_is_a_clear_error(monkeypatch):
    fake_ros(monkeypatch, True, [0.0])
    monkeypatch.setattr(rc, "FIRST_CLOCK_WAIT_S", 0.05)
    with pytest.raises(RuntimeError, match="start the simulated world"):
        rc.ros_clock()
