"""publish_pose.py: publishes a fixed goal (PoseStamped) at a rate, as in the chapter."""
from __future__ import annotations

import rospy
from geometry_msgs.msg import PoseStamped

from crazyflie_demo.rosutil import make_goal
from crazyflie_driver.nodes.ros_signals import init_node, publish_unless_shutting_down


def main() -> None:
    init_node("publish_pose", anonymous=True)
    name = rospy.get_param("~name", "goal")
    rate = float(rospy.get_param("~rate", 30.0))
    x = float(rospy.get_param("~x", 0.0))
    y = float(rospy.get_param("~y", 0.0))
    z = float(rospy.get_param("~z", 0.5))
    world_frame = rospy.get_param("~worldFrame", "world")
    pub = rospy.Publisher(name, PoseStamped, queue_size=1)
    r = rospy.Rate(rate)
    seq = 0
    while not rospy.is_shutdown():
        seq += 1
        if not publish_unless_shutting_down(pub, make_goal(world_frame, x, y, z, 0.0, seq)):
            break
        try:
            r.sleep()
        except rospy.ROSInterruptException:
            break
