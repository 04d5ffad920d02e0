"""publish_pose_teleop.py: a goal (PoseStamped) moved around by the joystick.

Sticks change the goal at a speed, not the vehicle directly: the position controller keeps
flying to wherever the goal is. Axes are 0-based indices into Joy.axes.
"""
from __future__ import annotations

import math
import threading
from typing import Optional

import rospy
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import Joy

from crazyflie_demo.rosutil import make_goal
from crazyflie_driver.nodes.ros_clock import ros_clock
from crazyflie_driver.nodes.ros_signals import init_node, publish_unless_shutting_down

#: The longest time one step integrates [s]: after a stall the goal moves on, it does not jump.
MAX_STEP_S = 0.1


class GoalTeleop:
    """ROS-free: integrates stick deflections into a goal position and yaw."""

    def __init__(self, x: float, y: float, z: float, speeds=(1.0, 1.0, 0.5, 2.0),
                 axes=(4, 3, 1, 0), deadzone: float = 0.1, z_min: float = 0.0) -> None:
        self.position = [x, y, z]
        self.yaw = 0.0
        self.speeds = speeds
        self.axes = axes
        self.deadzone = deadzone
        self.z_min = z_min

    def step(self, joy_axes, dt: float) -> None:
        def axis(i: int) -> float:
            v = joy_axes[i] if 0 <= i < len(joy_axes) else 0.0
            return v if abs(v) > self.deadzone else 0.0
        self.position[0] += axis(self.axes[0]) * self.speeds[0] * dt
        self.position[1] += axis(self.axes[1]) * self.speeds[1] * dt
        self.position[2] = max(self.z_min, self.position[2] + axis(self.axes[2]) * self.speeds[2] * dt)
        self.yaw = math.remainder(self.yaw + axis(self.axes[3]) * self.speeds[3] * dt, 2 * math.pi)


def main() -> None:
    init_node("publish_pose_teleop", anonymous=True)
    name = rospy.get_param("~name", "goal")
    rate = float(rospy.get_param("~rate", 30.0))
    joy_topic = rospy.get_param("~joy_topic", "joy")
    world_frame = rospy.get_param("~worldFrame", "world")
    teleop = GoalTeleop(float(rospy.get_param("~x", 0.0)), float(rospy.get_param("~y", 0.0)),
                        float(rospy.get_param("~z", 0.5)))
    lock = threading.Lock()
    last: dict = {"axes": None}

    def on_joy(msg: Joy) -> None:
        with lock:
            last["axes"] = list(msg.axes)

    rospy.Subscriber(joy_topic, Joy, on_joy, queue_size=1)
    pub = rospy.Publisher(name, PoseStamped, queue_size=1)
    r = rospy.Rate(rate)
    seq = 0
    clock = ros_clock()     # the goal moves at the stick's speed in the world's seconds
    stepped_at = clock.now()
    while not rospy.is_shutdown():
        with lock:
            axes: Optional[list] = last["axes"]
        now = clock.now()
        # the time that passed, so the goal moves at the stick's speed also when this loop runs late
        # (one period per loop, as the original node did, slows the goal down on a busy machine)
        dt, stepped_at = min(now - stepped_at, MAX_STEP_S), now
        if axes is not None:
            teleop.step(axes, dt)
        seq += 1
        x, y, z = teleop.position
        if not publish_unless_shutting_down(pub, make_goal(world_frame, x, y, z, teleop.yaw, seq)):
            break
        try:
            r.sleep()
        except rospy.ROSInterruptException:
            break
