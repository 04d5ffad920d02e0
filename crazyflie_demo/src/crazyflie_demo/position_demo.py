"""crazyflie_ros HEAD's ``Position.py``: one Crazyflie (the node's namespace) flies on
``cmd_position`` at 10 Hz: reset the Kalman filter, take off to 0.4 m, hold (0.2, 0.2, 0.4) for 3 s,
then (0, 0, 0) for 1 s, then ``cmd_stop``.

HEAD's plan, step by step: ``kalman/resetEstimation`` 1, 0.1 s, 0, 0.5 s; a take-off ramp of 10
steps of 0.04 m from 0 (to 0.36 m), 20 steps at 0.4 m; 3 s at (0.2, 0.2, 0.4); 1 s at (0, 0, 0);
stop. Positions are in the onboard estimator's frame: on hardware a Flow deck's (the start point is
the origin) or a positioning system's. Times are ROS time (the world's in a simulation).
"""
from __future__ import annotations

from typing import List, Tuple

import rospy
from std_msgs.msg import Empty

from crazyflie_driver.msg import Position
from crazyflie_driver.nodes.ros_signals import init_node, publish_unless_shutting_down, shutting_down
from crazyflie_driver.srv import UpdateParams

RATE_HZ = 10.0
STOP_FLUSH_S = 0.5   # s (ROS time) the node stays after its cmd_stop, so the message leaves
HEIGHT = 0.4                          # m
GOAL = (0.2, 0.2, HEIGHT)             # m
GOAL_S = 3.0                          # s at GOAL
LAND_S = 1.0                          # s at (0, 0, 0) before the stop

Target = Tuple[float, float, float]


def takeoff_targets() -> List[Target]:
    return [(0.0, 0.0, k / 25.0) for k in range(10)] + [(0.0, 0.0, HEIGHT)] * 20


class PositionFlight:
    def __init__(self) -> None:
        self.rate = rospy.Rate(RATE_HZ)
        self.msg = Position()
        self.msg.header.frame_id = rospy.get_param("~worldFrame", "/world")
        self.pub = rospy.Publisher("cmd_position", Position, queue_size=1)
        self.stop_pub = rospy.Publisher("cmd_stop", Empty, queue_size=1)
        rospy.wait_for_service("update_params")
        rospy.loginfo("found update_params service")
        self.update_params = rospy.ServiceProxy("update_params", UpdateParams)

    def send(self, target: Target) -> None:
        self.msg.x, self.msg.y, self.msg.z = target
        self.msg.yaw = 0.0
        self.msg.header.seq += 1
        self.msg.header.stamp = rospy.Time.now()
        publish_unless_shutting_down(self.pub, self.msg)
        self.rate.sleep()

    def hold(self, target: Target, seconds: float) -> None:
        start = rospy.get_time()
        while not shutting_down() and rospy.get_time() - start <= seconds:
            self.send(target)

    def run(self) -> None:
        for value, pause in ((1, 0.1), (0, 0.5)):
            rospy.set_param("kalman/resetEstimation", value)
            self.update_params(["kalman/resetEstimation"])
            rospy.sleep(pause)
        for target in takeoff_targets():
            if shutting_down():
                return
            self.send(target)
        self.hold(GOAL, GOAL_S)
        self.hold((0.0, 0.0, 0.0), LAND_S)
        if not shutting_down():
            publish_unless_shutting_down(self.stop_pub, Empty())
            rospy.sleep(STOP_FLUSH_S)    # the stop leaves before the node does


def main() -> None:
    init_node("position", anonymous=True)
    try:
        PositionFlight().run()
    except (rospy.ROSInterruptException, rospy.ServiceException) as e:
        if not shutting_down():
            rospy.logerr("Position.py: %s", e)
