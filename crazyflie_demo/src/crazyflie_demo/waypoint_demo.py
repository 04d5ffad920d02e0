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

    from crazyflie_demo.rosutil import say_launch_note, take_off_when_ready

    say_launch_note()
    flight = _WaypointFlight(demo, world, land_when_done)
    if takeoff:
        take_off_when_ready(TAKEOFF_TIMEOUT_S)
    rate = rospy.Rate(rate_hz)
    while not rospy.is_shutdown():
        if not flight.step(_lookup(flight.buffer, world, frame)):
            break
        try:
            rate.sleep()
        except rospy.ROSInterruptException:
            break
    return flight.done


class _WaypointFlight:
    """One flight through the waypoints: the follower, the tf buffer it reads the pose from, and the
    topics that publish the goal and the progress. Every publish returns False once ROS shuts down."""

    def __init__(self, demo: Demo, world: str, land_when_done: bool) -> None:
        import rospy
        import tf2_ros
        from geometry_msgs.msg import PointStamped, PoseStamped
        from std_msgs.msg import Bool, Int32

        self.demo, self.world, self.land_when_done = demo, world, land_when_done
        self.follower = follower_for(demo.goals)
        rospy.set_param("~waypoints", demo.goals)       # for monitors, in the chapter's units
        self.buffer = tf2_ros.Buffer()
        tf2_ros.TransformListener(self.buffer)
        self.goal_pub = rospy.Publisher("goal", PoseStamped, queue_size=1)
        self.index_pub = rospy.Publisher("~waypoint", Int32, queue_size=1, latch=True)
        self.reached_pub = rospy.Publisher("~reached", PointStamped, queue_size=len(demo.goals))
        self.done_pub = rospy.Publisher("~finished", Bool, queue_size=1, latch=True)
        self.done_pub.publish(Bool(False))
        self.seq, self.last_index, self.done = 0, -1, False

    def step(self, pose: Optional[Tuple[Tuple[float, float, float], float, object]]) -> bool:
        """One cycle with the newest pose (None: none fresh); False once ROS shuts down."""
        return self._note_pose(pose) and self._announce_waypoint() and self._send_goal() and self._finish()

    def _note_pose(self, pose: Optional[Tuple[Tuple[float, float, float], float, object]]) -> bool:
        """The follower sees the pose; a waypoint it counts as reached goes out on ``~reached``."""
        import rospy
        from geometry_msgs.msg import PointStamped

        from crazyflie_driver.nodes.ros_signals import publish_unless_shutting_down
        if pose is None:
            return True
        reached = len(self.follower.reached_times)
        self.follower.update(rospy.get_time(), pose[0], pose[1])
        if len(self.follower.reached_times) == reached:
            return True
        point = PointStamped()
        point.header.stamp, point.header.frame_id = pose[2], self.world
        point.point.x, point.point.y, point.point.z = pose[0]
        return publish_unless_shutting_down(self.reached_pub, point)

    def _announce_waypoint(self) -> bool:
        """A new waypoint to fly to goes out on ``~waypoint`` (and the log), once."""
        import rospy
        from std_msgs.msg import Int32

        from crazyflie_driver.nodes.ros_signals import publish_unless_shutting_down
        if self.follower.index == self.last_index:
            return True
        self.last_index = self.demo.goalIndex = self.follower.index
        if not publish_unless_shutting_down(self.index_pub, Int32(self.last_index)):
            return False
        rospy.loginfo("waypoint %d/%d: %s", self.last_index + 1, len(self.demo.goals), self.demo.goals[self.last_index])
        return True

    def _send_goal(self) -> bool:
        """The current waypoint as the controller's goal (every cycle, also while it is held)."""
        from crazyflie_demo.rosutil import make_goal
        from crazyflie_driver.nodes.ros_signals import publish_unless_shutting_down
        x, y, z, yaw, _sleep = self.demo.goals[self.follower.index]
        self.seq += 1
        return publish_unless_shutting_down(self.goal_pub, make_goal(self.world, x, y, z, yaw, self.seq))

    def _finish(self) -> bool:
        """Once every waypoint is reached: ``~finished`` true, and the landing when asked for."""
        import rospy
        from std_msgs.msg import Bool
        from std_srvs.srv import Empty

        from crazyflie_demo.rosutil import wait_for_service
        from crazyflie_driver.nodes.ros_signals import publish_unless_shutting_down
        if not self.follower.finished or self.done:
            return True
        self.done = True
        if not publish_unless_shutting_down(self.done_pub, Bool(True)):
            return False
        rospy.loginfo("all %d waypoints reached", len(self.demo.goals))
        if self.land_when_done and wait_for_service("land", LAND_SERVICE_TIMEOUT_S):
            try:
                rospy.ServiceProxy("land", Empty)()
            except rospy.ServiceException as exc:
                rospy.logerr("land failed: %s", exc)
        return True


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
