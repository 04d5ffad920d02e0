"""ROS time as the stack's ``Clock``: the world's ``/clock`` in simulation, the wall clock on hardware.

Under ``/use_sim_time`` rospy's time follows ``/clock``, which the simulated world publishes; the
server's workers, the safety reactions, the controllers and the monitors then time everything in
world seconds, so a world slowed down by a busy machine slows them with it. Without it (hardware,
or a simulation run on the wall clock) this is ``clock.WALL``, exactly as before.
"""
from __future__ import annotations

import time

import rospy

from crazyflie_driver.clock import WALL, Clock, FollowingClock

FIRST_CLOCK_WAIT_S = 30.0
"""Wall seconds [s] to wait for the first ``/clock`` message under ``/use_sim_time`` before saying so."""


def uses_sim_time() -> bool:
    """Whether this node's ROS time follows ``/clock`` (the global parameter ``/use_sim_time``)."""
    return bool(rospy.get_param("/use_sim_time", False))


def ros_clock(max_speed: float = 1.0) -> Clock:
    """The clock this node's timing decisions read (call after ``rospy.init_node``).

    Under ``/use_sim_time`` it waits (up to FIRST_CLOCK_WAIT_S of wall time, warning every 5 s) for
    the first ``/clock``, so no timeout is computed from ROS time 0. ``max_speed``: the most world
    seconds per wall second the world may run at (``FollowingClock``).
    """
    if not uses_sim_time():
        return WALL
    start = time.monotonic()
    warned = start
    while rospy.get_time() == 0.0 and not rospy.is_shutdown():
        now = time.monotonic()
        if now - start > FIRST_CLOCK_WAIT_S:
            raise RuntimeError("/use_sim_time is set but nothing published /clock for %.0f s: start the "
                               "simulated world (sim.launch) or unset /use_sim_time" % FIRST_CLOCK_WAIT_S)
        if now - warned > 5.0:
            rospy.logwarn("waiting for /clock (/use_sim_time is set): is the simulated world running?")
            warned = now
        time.sleep(0.01)
    return FollowingClock(rospy.get_time, max_speed=max_speed)
