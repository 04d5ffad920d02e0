"""nodes.ros_clock: the wall clock on hardware (no /use_sim_time), ROS time that follows /clock in simulation."""
from __future__ import annotations

import time

import pytest

rospy = pytest.importorskip("rospy")

from crazyflie_driver.clock import WALL, FollowingClock  # noqa: E402
from crazyflie_driver.nodes import ros_clock  # noqa: E402


def params(values):
    return lambda name, default=None: values.get(name, default)


def test_without_use_sim_time_every_timing_decision_is_on_the_wall_clock(monkeypatch):
    """Hardware: nothing sets /use_sim_time and nothing publishes /clock; ROS time is never consulted."""
    monkeypatch.setattr(rospy, "get_param", params({}))
    monkeypatch.setattr(rospy, "get_time", lambda: pytest.fail("ROS time read on hardware"))
    assert ros_clock.uses_sim_time() is False
    assert ros_clock.ros_clock() is WALL
    assert abs(ros_clock.ros_clock().now() - time.monotonic()) < 0.01
    monkeypatch.setattr(rospy, "get_param", params({"/use_sim_time": False}))
    assert ros_clock.ros_clock() is WALL


def test_under_use_sim_time_the_clock_follows_ros_time_once_clock_has_come(monkeypatch):
    ros_now = [0.0]
    monkeypatch.setattr(rospy, "get_param", params({"/use_sim_time": True}))
    monkeypatch.setattr(rospy, "get_time", lambda: ros_now[0])
    monkeypatch.setattr(rospy, "is_shutdown", lambda: False)

    def first_clock(seconds):                 # the world's first /clock arrives while the node waits
        ros_now[0] = 12.5
    monkeypatch.setattr(ros_clock.time, "sleep", first_clock)
    clock = ros_clock.ros_clock(max_speed=1.0)
    assert isinstance(clock, FollowingClock)
    assert clock.now() == 12.5
    ros_now[0] = 13.0
    assert clock.now() == 13.0
