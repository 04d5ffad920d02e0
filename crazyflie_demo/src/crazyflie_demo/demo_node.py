"""demo.py: fly a list of waypoints with the position controller (chapter's demo1/demo2).

Publishes the current waypoint as ``goal`` and advances when the vehicle (tf worldFrame →
frame) is within 0.3 m on each axis and 10° in yaw and has stayed there for the waypoint's
sleep time. With ``~takeoff`` it calls the controller's takeoff service first, and with
``~land_when_done`` it lands after the last waypoint (used by sim:=true runs without a
joystick). Progress is published on ``~waypoint`` (std_msgs/Int32, the current index) and
``~finished`` (std_msgs/Bool).
"""
from __future__ import annotations

import math
from typing import Optional, Sequence

import rospy
import tf2_ros
from geometry_msgs.msg import PoseStamped
from std_msgs.msg import Bool, Int32
from std_srvs.srv import Empty

from crazyflie_demo.rosutil import make_goal, quaternion_to_yaw, take_off_when_ready, wait_for_service
from crazyflie_demo.waypoints import WaypointFollower
from crazyflie_driver.nodes.ros_signals import init_node, publish_unless_shutting_down


def _lookup(buffer: tf2_ros.Buffer, world: str, frame: str, max_age: float):
    try:
        t = buffer.lookup_transform(world, frame, rospy.Time(0), rospy.Duration(0.05))
    except (tf2_ros.LookupException, tf2_ros.ConnectivityException,
            tf2_ros.ExtrapolationException):
        return None
    if (rospy.Time.now() - t.header.stamp).to_sec() > max_age:
        return None
    p, q = t.transform.translation, t.transform.rotation
    return (p.x, p.y, p.z), math.degrees(quaternion_to_yaw(q.x, q.y, q.z, q.w))


def run(waypoints: Optional[Sequence[Sequence[float]]] = None) -> None:
    """Start the node; ``waypoints`` None reads them from the private parameter ~waypoints."""
    init_node("demo", anonymous=True)
    if waypoints is None:
        waypoints = rospy.get_param("~waypoints", [[0.0, 0.0, 0.5, 0.0, 2.0]])
    # tf2 refuses frame ids with a leading '/', which the chapter's launch files use
    world = str(rospy.get_param("~worldFrame", "world")).strip("/")
    frame = str(rospy.get_param("~frame", "")).strip("/")
    rate = float(rospy.get_param("~rate", 30.0))
    takeoff = bool(rospy.get_param("~takeoff", False))
    land_when_done = bool(rospy.get_param("~land_when_done", False))
    if not frame:
        rospy.logfatal("demo: the private parameter ~frame (the vehicle's tf frame) is required")
        return
    follower = WaypointFollower(waypoints)
    rospy.set_param("~waypoints", [list(map(float, w)) for w in waypoints])  # for monitors
    buffer = tf2_ros.Buffer()
    tf2_ros.TransformListener(buffer)
    goal_pub = rospy.Publisher("goal", PoseStamped, queue_size=1)
    index_pub = rospy.Publisher("~waypoint", Int32, queue_size=1, latch=True)
    done_pub = rospy.Publisher("~finished", Bool, queue_size=1, latch=True)
    done_pub.publish(Bool(False))
    if takeoff:
        take_off_when_ready(60.0)
    r = rospy.Rate(rate)
    seq, last_index, landed = 0, -1, False
    while not rospy.is_shutdown():
        pose = _lookup(buffer, world, frame, max_age=0.5)
        if pose is not None:
            follower.update(rospy.get_time(), pose[0], pose[1])
        if follower.index != last_index:
            last_index = follower.index
            if not publish_unless_shutting_down(index_pub, Int32(last_index)):
                break
            rospy.loginfo("waypoint %d/%d: %s", last_index + 1, len(follower.waypoints),
                          follower.current)
        w = follower.current
        seq += 1
        if not publish_unless_shutting_down(goal_pub, make_goal(world, w.x, w.y, w.z,
                                                                math.radians(w.yaw_deg), seq)):
            break
        if follower.finished and not landed:
            landed = True
            if not publish_unless_shutting_down(done_pub, Bool(True)):
                break
            rospy.loginfo("all %d waypoints reached", len(follower.waypoints))
            if land_when_done and wait_for_service("land", 5.0):
                try:
                    rospy.ServiceProxy("land", Empty)()
                except rospy.ServiceException as exc:
                    rospy.logerr("land failed: %s", exc)
        try:
            r.sleep()
        except rospy.ROSInterruptException:
            break


def main() -> None:
    run(None)
