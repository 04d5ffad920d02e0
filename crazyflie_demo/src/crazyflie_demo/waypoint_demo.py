"""The chapter's ``Demo`` class: fly ``[x, y, z, yaw, sleep]`` waypoints with the position controller.

``Demo(goals).run()`` publishes the current waypoint as ``goal`` (yaw in radians, as in the
chapter) and moves on once the vehicle (tf ``worldFrame → frame``) is within 0.3 m on each axis
and 10° in yaw and has stayed there ``sleep`` seconds. Constructing a Demo needs no ROS master;
``run()`` starts the node ``demo`` (anonymous) unless the process already is one.

Beyond the chapter: ``~takeoff`` calls the controller's ``takeoff`` service first and
``~land_when_done`` lands after the last waypoint (sim:=true runs without a joystick); progress is
published on ``~waypoint`` (std_msgs/Int32, the index flown to), ``~reached``
(geometry_msgs/PointStamped: each time a waypoint counts as reached, the position that decided it,
stamped with that pose's time) and ``~finished`` (std_msgs/Bool), and the waypoints themselves are
put on ``~waypoints`` for monitors. Unlike the chapter's blocking
sleep, the goal keeps being published while a waypoint is held, and drifting away restarts the wait.
"""
from __future__ import annotations

import math
from typing import List, Optional, Sequence, Tuple

from crazyflie_demo.waypoints import WaypointFollower

NODE_NAME = "demo"
DEFAULT_RATE_HZ = 30.0
POSE_MAX_AGE_S = 0.5        # an older tf pose does not count as being at a waypoint
TAKEOFF_TIMEOUT_S = 60.0
LAND_SERVICE_TIMEOUT_S = 5.0


def check_goals(goals: Sequence[Sequence[float]]) -> List[List[float]]:
    """``goals`` as floats, or ValueError naming the bad entry (the chapter's order: x, y, z, yaw rad, sleep s)."""
    if not goals:
        raise ValueError("Demo needs at least one waypoint [x, y, z, yaw, sleep]")
    out = []
    for i, g in enumerate(goals):
        try:
            values = [float(v) for v in g]
        except (TypeError, ValueError):
            raise ValueError("waypoint %d %r is not 5 numbers [x, y, z, yaw (rad), sleep (s)]" % (i + 1, g)) from None
        if len(values) != 5 or not all(math.isfinite(v) for v in values):
            raise ValueError("waypoint %d %r is not 5 finite numbers [x, y, z, yaw (rad), sleep (s)]" % (i + 1, g))
        if values[4] < 0:
            raise ValueError("waypoint %d: sleep %r s is negative" % (i + 1, values[4]))
        out.append(values)
    return out


def follower_for(goals: Sequence[Sequence[float]]) -> WaypointFollower:
    """The sequencer over ``goals`` (yaw in radians, which the follower takes in degrees)."""
    return WaypointFollower([[x, y, z, math.degrees(yaw), sleep] for x, y, z, yaw, sleep in check_goals(goals)])


class Demo:
    """The chapter's waypoint demo: ``Demo([[x, y, z, yaw, sleep], ...]).run()``."""

    def __init__(self, goals: Sequence[Sequence[float]]) -> None:
        self.goals = check_goals(goals)
        self.goalIndex = 0          # the chapter's name: index of the waypoint flown to

    def run(self) -> bool:
        """Fly until shut down; True once every waypoint was reached (the node keeps holding the last)."""
        import rospy

        from crazyflie_driver.nodes.ros_signals import init_node
        if not rospy.core.is_initialized():
            init_node(NODE_NAME, anonymous=True)
        frame = str(rospy.get_param("~frame", "")).strip("/")   # tf2 refuses a leading '/'
        if not frame:
            rospy.logfatal("demo: the private parameter ~frame (the vehicle's tf frame) is required")
            return False
        world = str(rospy.get_param("~worldFrame", "world")).strip("/") or "world"
        return _fly(self, world, frame, float(rospy.get_param("~rate", DEFAULT_RATE_HZ)),
                    bool(rospy.get_param("~takeoff", False)), bool(rospy.get_param("~land_when_done", False)))


def _lookup(buffer, world: str, frame: str) -> Optional[Tuple[Tuple[float, float, float], float, object]]:
    """(position, yaw in degrees, the pose's stamp) of ``frame`` in ``world``, or None when unknown or too old."""
    import rospy
    import tf2_ros

    from crazyflie_demo.rosutil import quaternion_to_yaw
    try:
        t = buffer.lookup_transform(world, frame, rospy.Time(0), rospy.Duration(0.05))
    except (tf2_ros.LookupException, tf2_ros.ConnectivityException, tf2_ros.ExtrapolationException):
        return None
    if (rospy.Time.now() - t.header.stamp).to_sec() > POSE_MAX_AGE_S:
        return None
    p, q = t.transform.translation, t.transform.rotation
    return (p.x, p.y, p.z), math.degrees(quaternion_to_yaw(q.x, q.y, q.z, q.w)), t.header.stamp


def _fly(demo: Demo, world: str, frame: str, rate_hz: float, takeoff: bool, land_when_done: bool) -> bool:
    import rospy
    import tf2_ros
    from geometry_msgs.msg import PointStamped, PoseStamped
    from std_msgs.msg import Bool, Int32
    from std_srvs.srv import Empty

    from crazyflie_demo.rosutil import make_goal, say_launch_note, take_off_when_ready, wait_for_service
    from crazyflie_driver.nodes.ros_signals import publish_unless_shutting_down

    say_launch_note()
    follower = follower_for(demo.goals)
    rospy.set_param("~waypoints", demo.goals)       # for monitors, in the chapter's units
    buffer = tf2_ros.Buffer()
    tf2_ros.TransformListener(buffer)
    goal_pub = rospy.Publisher("goal", PoseStamped, queue_size=1)
    index_pub = rospy.Publisher("~waypoint", Int32, queue_size=1, latch=True)
    reached_pub = rospy.Publisher("~reached", PointStamped, queue_size=len(demo.goals))
    done_pub = rospy.Publisher("~finished", Bool, queue_size=1, latch=True)
    done_pub.publish(Bool(False))
    if takeoff:
        take_off_when_ready(TAKEOFF_TIMEOUT_S)
    rate = rospy.Rate(rate_hz)
    seq, last_index, done = 0, -1, False
    while not rospy.is_shutdown():
        pose = _lookup(buffer, world, frame)
        if pose is not None:
            reached = len(follower.reached_times)
            follower.update(rospy.get_time(), pose[0], pose[1])
            if len(follower.reached_times) > reached:
                point = PointStamped()
                point.header.stamp, point.header.frame_id = pose[2], world
                point.point.x, point.point.y, point.point.z = pose[0]
                if not publish_unless_shutting_down(reached_pub, point):
                    break
        if follower.index != last_index:
            last_index = demo.goalIndex = follower.index
            if not publish_unless_shutting_down(index_pub, Int32(last_index)):
                break
            rospy.loginfo("waypoint %d/%d: %s", last_index + 1, len(demo.goals), demo.goals[last_index])
        x, y, z, yaw, _sleep = demo.goals[follower.index]
        seq += 1
        if not publish_unless_shutting_down(goal_pub, make_goal(world, x, y, z, yaw, seq)):
            break
        if follower.finished and not done:
            done = True
            if not publish_unless_shutting_down(done_pub, Bool(True)):
                break
            rospy.loginfo("all %d waypoints reached", len(demo.goals))
            if land_when_done and wait_for_service("land", LAND_SERVICE_TIMEOUT_S):
                try:
                    rospy.ServiceProxy("land", Empty)()
                except rospy.ServiceException as exc:
                    rospy.logerr("land failed: %s", exc)
        try:
            rate.sleep()
        except rospy.ROSInterruptException:
            break
    return done


def main() -> None:
    """scripts/demo.py run on its own: the waypoints come from the private parameter ~waypoints."""
    import rospy

    from crazyflie_driver.nodes.ros_signals import init_node
    init_node(NODE_NAME, anonymous=True)
    try:
        demo = Demo(rospy.get_param("~waypoints", [[0.0, 0.0, 0.5, 0.0, 2.0]]))
    except ValueError as exc:
        rospy.logfatal("demo: ~waypoints: %s", exc)
        return
    demo.run()
