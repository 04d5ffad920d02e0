"""autopilot.py: takes off, hovers for a while and lands, for runs without a joystick.

Used by the launch files' ``auto`` argument (default on with ``sim:=true``): it calls the
position controller's ``takeoff`` service once the Crazyflie is added and the controller has a
pose (asking again if it was refused), and ``land`` after
``~hover_time`` seconds (0 keeps hovering until shut down). ``~note``, if set, is logged at start:
the launch file's line on how to get the chapter's behaviour instead (``auto:=false``).
"""
from __future__ import annotations

import rospy
from std_srvs.srv import Empty

from crazyflie_demo.rosutil import say_launch_note, take_off_when_ready
from crazyflie_driver.nodes.ros_signals import init_node


def main() -> None:
    init_node("autopilot")
    say_launch_note()
    delay = float(rospy.get_param("~takeoff_delay", 0.0))
    hover_time = float(rospy.get_param("~hover_time", 0.0))
    rospy.sleep(delay)
    if not take_off_when_ready(60.0):
        return
    rospy.loginfo("autopilot: takeoff")
    if hover_time <= 0.0:
        rospy.spin()
        return
    rospy.sleep(hover_time)
    if rospy.is_shutdown():
        return
    try:
        rospy.ServiceProxy("land", Empty)()
        rospy.loginfo("autopilot: land")
    except rospy.ServiceException as exc:
        rospy.logerr("autopilot: land failed: %s", exc)
    rospy.spin()
