"""Small rospy helpers shared by the demo nodes (imported only inside nodes)."""
from __future__ import annotations

import math
import time
from typing import Optional, Tuple

import rospy
from geometry_msgs.msg import PoseStamped

from crazyflie_driver.mocap.frames import yaw_of
from crazyflie_driver.nodes.ros_signals import shutting_down


def yaw_to_quaternion(yaw_rad: float) -> Tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation about z."""
    return (0.0, 0.0, math.sin(yaw_rad / 2.0), math.cos(yaw_rad / 2.0))


def quaternion_to_yaw(x: float, y: float, z: float, w: float) -> float:
    """Yaw (rad) of a quaternion, ZYX convention."""
    return yaw_of((x, y, z, w))


def make_goal(frame_id: str, x: float, y: float, z: float, yaw_rad: float,
              seq: int = 0, stamp: Optional[rospy.Time] = None) -> PoseStamped:
    msg = PoseStamped()
    msg.header.seq = seq
    msg.header.frame_id = frame_id.strip("/")   # tf2 refuses a leading slash
    msg.header.stamp = stamp if stamp is not None else rospy.Time.now()
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = x, y, z
    q = yaw_to_quaternion(yaw_rad)
    (msg.pose.orientation.x, msg.pose.orientation.y,
     msg.pose.orientation.z, msg.pose.orientation.w) = q
    return msg


def say_launch_note() -> None:
    """Log the private parameter ``~note`` once, if set: a launch file's one line on what it does
    differently from the chapter's and how to get the chapter's behaviour."""
    note = str(rospy.get_param("~note", "")).strip()
    if note:
        rospy.loginfo(note)


def wait_for_service(name: str, timeout: float) -> bool:
    """Wait for a service; False (and a log line) instead of an exception on timeout.

    False without a log line when the node is shutting down (rospy interrupts the wait).
    """
    try:
        rospy.wait_for_service(name, timeout=timeout)
        return True
    except rospy.ROSInterruptException:
        return False
    except rospy.ROSException:
        rospy.logwarn("service %s not available after %.0f s", rospy.resolve_name(name), timeout)
        return False


def take_off_when_ready(timeout: float, state_topic: str = "controller/state") -> bool:
    """Call the position controller's ``takeoff`` once it can act on it, and confirm it did.

    Ready means the Crazyflie is on the server (its ``emergency`` service exists) and the
    controller reports a fresh pose (``~state`` "Idle: ok"); a take-off the controller refused is
    asked again. False (and a log line) if it has not taken off after ``timeout`` seconds.
    """
    from std_msgs.msg import String
    from std_srvs.srv import Empty

    deadline = rospy.get_time() + timeout
    if not (wait_for_service("emergency", timeout) and wait_for_service("takeoff", timeout)):
        return False
    status = {"text": ""}

    def on_state(msg: String) -> None:
        status["text"] = msg.data

    sub = rospy.Subscriber(state_topic, String, on_state, queue_size=5)
    takeoff = rospy.ServiceProxy("takeoff", Empty)
    try:
        while not rospy.is_shutdown() and rospy.get_time() < deadline:
            text = status["text"]
            if text and not text.startswith("Idle"):
                return True
            if text.startswith("Idle: ok"):
                try:
                    takeoff()
                except rospy.ServiceException as exc:
                    rospy.logwarn("takeoff failed: %s", exc)
            rospy.sleep(0.5)
    except rospy.ROSInterruptException:
        return False
    finally:
        sub.unregister()
    if not shutting_down():
        rospy.logerr("no take-off after %.0f s (controller state: %r)", timeout, status["text"])
    return False


class RealTimeFactor:
    """How fast the world ran over a demo: ROS (world) seconds per wall second since ``__init__``.

    Under /use_sim_time ROS time is the simulated world's; its ``speed`` setting is read from the sim
    node (``sim_node``'s ``~speed``). Without /use_sim_time ROS time is the wall clock and the line says so.
    """

    def __init__(self, sim_node: str = "/crazyflie_sim") -> None:
        self._ros0, self._wall0 = rospy.get_time(), time.monotonic()
        self._sim_node = sim_node

    def line(self) -> str:
        if not rospy.get_param("/use_sim_time", False):
            return "world time: the wall clock (no /use_sim_time)"
        wall = time.monotonic() - self._wall0
        factor = (rospy.get_time() - self._ros0) / wall if wall > 0 else 0.0
        speed = rospy.get_param(self._sim_node.rstrip("/") + "/speed", "1.0")
        return "world ran at %.2fx real time on average (speed %s, %.0f s wall clock)" % (factor, speed, wall)
