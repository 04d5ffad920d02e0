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
    seconds per wall second the world may run at (``FollowingClock``). Once rospy has shut down
    (no /clock is heard any more) its waits end on the wall clock.
    """
    if not uses_sim_time():
        return WALL
    _wait_for_first(rospy.get_time, "/clock (/use_sim_time is set)")
    return FollowingClock(rospy.get_time, max_speed=max_speed, stopped=rospy.is_shutdown)


def topic_clock(topic: str, max_speed: float = 1.0) -> Clock:
    """A clock on the time a ``rosgraph_msgs/Clock`` topic carries, for a node that follows the world's
    ``/clock`` while ROS time stays on the wall clock (no ``/use_sim_time``); ``ros_clock()`` when it is set."""
    if uses_sim_time():
        return ros_clock(max_speed)
    from rosgraph_msgs.msg import Clock as ClockMsg

    latest = [0.0]

    def on_clock(msg) -> None:
        latest[0] = msg.clock.to_sec()
    rospy.Subscriber(topic, ClockMsg, on_clock, queue_size=1)
    _wait_for_first(lambda: latest[0], topic)
    return FollowingClock(lambda: latest[0], max_speed=max_speed, stopped=rospy.is_shutdown)


def _wait_for_first(now, what: str) -> None:
    """Until ``now()`` leaves 0 (the first time message arrived), warning every 5 s; RuntimeError after
    FIRST_CLOCK_WAIT_S. Wall seconds: the clock to wait on is not there yet."""
    start = time.monotonic()
    warned = start
    while now() == 0.0 and not rospy.is_shutdown():
        t = time.monotonic()
        if t - start > FIRST_CLOCK_WAIT_S:
            raise RuntimeError("nothing published %s for %.0f s: start the simulated world (sim.launch) or unset "
                               "/use_sim_time" % (what, FIRST_CLOCK_WAIT_S))
        if t - warned > 5.0:
            rospy.logwarn("waiting for %s: is the simulated world running?" % what)
            warned = t
        time.sleep(0.01)
