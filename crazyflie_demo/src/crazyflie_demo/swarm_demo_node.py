"""``swarm_demo``: the swarm flight through crazyflie_server's swarm-wide and per-Crazyflie services.

Reads the swarm file (``~swarm_file``, the one the server flies), uploads the figure-8 once to every
Crazyflie (``/<cf>/upload_trajectory``, several at once), then: ``/takeoff`` (one broadcast),
``/start_trajectory`` (one broadcast, relative to each start), a formation change with one
``/<cf>/go_to`` each (a stepped pyramid over the grid), ``/land``. Each phase is announced on
``~phase`` (std_msgs/String, JSON, see ``swarm_flight.Phase``) just before its command, for monitors
and tests.

Waits follow ROS time (``ros_clock``: the world's under ``/use_sim_time``), or ``~clock_topic`` when set
without it (the simulated world's ``/clock``): phases keep their length in world time even when the
world runs behind real time; else the wall clock, as on hardware.
``~height`` (1.0 m), ``~timeout`` (s to wait for the server's services, default 120).
"""
from __future__ import annotations

from typing import Callable, Dict

import rospy
from std_msgs.msg import String

from crazyflie_demo.figure8 import figure8_pieces, trajectory_duration
from crazyflie_demo.swarm_flight import (
    FORMATION_S,
    LAND_S,
    SETTLE_S,
    TAKEOFF_HEIGHT_M,
    TAKEOFF_S,
    TRAJECTORY_ID,
    Phase,
    pyramid_goals,
)
from crazyflie_driver.clock import Clock
from crazyflie_driver.nodes.ros_clock import ros_clock, topic_clock
from crazyflie_driver.nodes.ros_signals import init_node, shutting_down
from crazyflie_driver.server.swarm.config import load_swarm_file

PARALLEL_CALLS = 16


def pause(clock: Clock, seconds: float) -> bool:
    """``seconds`` of ``clock``'s time; False when the node shuts down first (looked at every 0.1 s)."""
    end = clock.now() + seconds
    while not shutting_down():
        left = end - clock.now()
        if left <= 0:
            return True
        clock.sleep(min(left, 0.1))
    return False


def _pieces_msg():
    from crazyflie_driver.msg import TrajectoryPolynomialPiece

    out = []
    for p in figure8_pieces():
        m = TrajectoryPolynomialPiece()
        m.poly_x, m.poly_y, m.poly_z, m.poly_yaw = list(p.x), list(p.y), list(p.z), list(p.yaw)
        m.duration = rospy.Duration.from_sec(p.duration)
        out.append(m)
    return out


def fly(names, initial: Dict[str, tuple], announce: Callable[[Phase], None], clock: Clock,
        timeout: float, height: float = TAKEOFF_HEIGHT_M) -> bool:
    """The whole flight; False (logged) when a service is missing or refuses."""
    from crazyflie_driver.srv import GoTo, Land, StartTrajectory, Takeoff, UploadTrajectory

    needed = ["/takeoff", "/land", "/start_trajectory"] + ["/%s/%s" % (n, s) for n in names
                                                           for s in ("upload_trajectory", "go_to")]
    for name in needed:
        try:
            rospy.wait_for_service(name, timeout=timeout)
        except rospy.ROSException:
            if not shutting_down():
                rospy.logerr("swarm_demo: %s is not served after %.0f s: is crazyflie_server running in swarm mode "
                             "with every Crazyflie of the swarm file connected?", name, timeout)
            return False
    pieces = _pieces_msg()
    duration = trajectory_duration(figure8_pieces())
    try:
        each(names, lambda n: rospy.ServiceProxy("/%s/upload_trajectory" % n, UploadTrajectory)(
            TRAJECTORY_ID, 0, pieces))
        rospy.loginfo("swarm_demo: figure-8 (%d pieces, %.1f s) uploaded to %d Crazyflies", len(pieces), duration,
                      len(names))

        announce(Phase("takeoff", TAKEOFF_S, height))
        rospy.ServiceProxy("/takeoff", Takeoff)(0, height, rospy.Duration.from_sec(TAKEOFF_S))
        if not pause(clock, TAKEOFF_S + SETTLE_S):
            return False

        announce(Phase("figure8", duration))
        rospy.ServiceProxy("/start_trajectory", StartTrajectory)(0, TRAJECTORY_ID, 1.0, False, True)
        if not pause(clock, duration + SETTLE_S):
            return False

        goals = pyramid_goals({n: (initial[n][0], initial[n][1], height) for n in names}, height)
        announce(Phase("formation", FORMATION_S, goals=goals))
        each(names, lambda n: rospy.ServiceProxy("/%s/go_to" % n, GoTo)(
            0, False, _point(goals[n]), 0.0, rospy.Duration.from_sec(FORMATION_S)))
        if not pause(clock, FORMATION_S + SETTLE_S):
            return False

        announce(Phase("land", LAND_S, 0.0))
        rospy.ServiceProxy("/land", Land)(0, 0.0, rospy.Duration.from_sec(LAND_S))
        if not pause(clock, LAND_S + SETTLE_S):
            return False
    except (rospy.ServiceException, rospy.ROSException) as e:
        if not shutting_down():
            rospy.logerr("swarm_demo: a command failed: %s", e)
        return False
    announce(Phase("done"))
    return True


def each(names, call: Callable[[str], object]) -> None:
    """``call(name)`` for every Crazyflie, several at once (the server serves them in parallel);
    the first failure is raised after all have been tried."""
    from concurrent.futures import ThreadPoolExecutor
    with ThreadPoolExecutor(max_workers=min(PARALLEL_CALLS, len(names))) as pool:
        futures = [pool.submit(call, n) for n in names]
    for f in futures:
        f.result()


def _point(p):
    from geometry_msgs.msg import Point
    return Point(float(p[0]), float(p[1]), float(p[2]))


def main() -> None:
    init_node("swarm_demo")
    path = str(rospy.get_param("~swarm_file", ""))
    try:
        config = load_swarm_file(path)
    except Exception as e:          # SwarmConfigError names the file, the line and the fix
        rospy.logfatal("swarm_demo: %s", e)
        raise SystemExit(1) from None
    names = [cf.name for cf in config.crazyflies]
    initial = {cf.name: cf.initial_position for cf in config.crazyflies}
    pub = rospy.Publisher("~phase", String, queue_size=10, latch=True)

    def announce(phase: Phase) -> None:
        rospy.loginfo("swarm_demo: %s%s", phase.name,
                      " (%.1f s)" % phase.duration if phase.duration else "")
        pub.publish(String(phase.to_json()))

    topic = str(rospy.get_param("~clock_topic", ""))
    try:
        clock = topic_clock(topic) if topic else ros_clock()
    except RuntimeError as e:       # no /clock from the world
        rospy.logfatal("swarm_demo: %s", e)
        raise SystemExit(1) from None
    ok = fly(names, initial, announce, clock, float(rospy.get_param("~timeout", 120.0)),
             float(rospy.get_param("~height", TAKEOFF_HEIGHT_M)))
    if not ok and not shutting_down():
        raise SystemExit(1)
    if not shutting_down():
        rospy.loginfo("swarm_demo: done (%d Crazyflies)", len(names))
        rospy.spin()          # keep ~phase latched for late listeners until roslaunch stops
