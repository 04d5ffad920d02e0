"""joy_node: a Linux joystick as sensor_msgs/Joy on ``joy``, with the ROS joy package's parameters.

Private params: ``~dev`` (/dev/input/js0), ``~deadzone`` (0.05), ``~autorepeat_rate`` (20 Hz; 0 = off),
``~coalesce_interval`` (0.001 s). A missing device is retried every second; an unplugged one is
reported as a neutral message (all axes 0, buttons released) and reopened.

The joy package's autorepeat is off by default; ours repeats the state while the pad is connected,
because a Crazyflie gets a setpoint only when a Joy message arrives: a stick held still would
otherwise let the firmware's 2 s setpoint watchdog cut (and, on current firmware, lock) the motors.
"""
from __future__ import annotations

import logging

import rospy
from sensor_msgs.msg import Joy

from crazyflie_demo.joystick import JoyState, Joystick
from crazyflie_driver.nodes.ros_signals import RosLogHandler, init_node, publish_unless_shutting_down

DEFAULT_AUTOREPEAT_HZ = 20.0   # well inside the firmware's 2 s watchdog (and its 0.5 s level-off)


def to_message(state: JoyState, frame_id: str) -> Joy:
    msg = Joy()
    msg.header.stamp = rospy.Time.now()
    msg.header.frame_id = frame_id
    msg.axes = list(state.axes)
    msg.buttons = list(state.buttons)
    return msg


def main() -> None:
    init_node("joy_node")
    logger = logging.getLogger("crazyflie_demo.joy_node")
    logger.propagate = False
    logger.addHandler(RosLogHandler())
    logger.setLevel(logging.INFO)
    dev = str(rospy.get_param("~dev", "/dev/input/js0"))
    try:
        joystick = Joystick(dev=dev,
                            deadzone=float(rospy.get_param("~deadzone", 0.05)),
                            autorepeat_rate=float(rospy.get_param("~autorepeat_rate", DEFAULT_AUTOREPEAT_HZ)),
                            coalesce_interval=float(rospy.get_param("~coalesce_interval", 0.001)),
                            logger=logger)
    except (TypeError, ValueError) as exc:
        rospy.logfatal("joy_node: bad parameter: %s", exc)
        return
    pub = rospy.Publisher("joy", Joy, queue_size=10)
    rospy.loginfo("joy_node: reading %s, publishing %s (repeated at %.0f Hz while the pad is still)",
                  dev, pub.resolved_name, joystick.autorepeat_rate)
    try:
        for state in joystick.states(timeout=0.1, should_stop=rospy.is_shutdown):
            if not publish_unless_shutting_down(pub, to_message(state, dev)):
                break
    except rospy.ROSInterruptException:
        pass
    finally:
        joystick.close()
