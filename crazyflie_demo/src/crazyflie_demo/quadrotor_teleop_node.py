"""quadrotor_teleop: ``joy`` (sensor_msgs/Joy) -> ``cmd_vel`` (geometry_msgs/Twist).

Parameters as hector_quadrotor_teleop: ``~x_axis``, ``~y_axis``, ``~z_axis``, ``~yaw_axis``
(1-based, negative inverts, 0 disables) and ``~x_velocity_max``, ``~y_velocity_max``,
``~z_velocity_max``, ``~yaw_velocity_max``; plus ``~z_min`` (optional lower bound of linear.z,
0 in our launch files so the thrust is never negative). One Twist per Joy message; a zero Twist
on shutdown.
"""
from __future__ import annotations

import rospy
from geometry_msgs.msg import Twist
from sensor_msgs.msg import Joy

from crazyflie_demo.teleop import TeleopConfig, TeleopConfigError, TwistCommand
from crazyflie_driver.nodes.ros_signals import init_node, publish_unless_shutting_down


def to_twist(cmd: TwistCommand) -> Twist:
    msg = Twist()
    msg.linear.x, msg.linear.y, msg.linear.z = cmd.linear_x, cmd.linear_y, cmd.linear_z
    msg.angular.z = cmd.angular_z
    return msg


def main() -> None:
    init_node("quadrotor_teleop")
    try:
        config = TeleopConfig.from_params(lambda name, default: rospy.get_param("~" + name, default))
    except TeleopConfigError as exc:
        rospy.logfatal("quadrotor_teleop: %s", exc)
        return
    pub = rospy.Publisher("cmd_vel", Twist, queue_size=10)

    def on_joy(msg: Joy) -> None:
        publish_unless_shutting_down(pub, to_twist(config.command(msg.axes)))

    def stop() -> None:
        try:                             # best effort: the connections may be closing already
            if pub.get_num_connections() > 0:
                pub.publish(Twist())
        except rospy.ROSException:
            pass

    rospy.Subscriber("joy", Joy, on_joy, queue_size=1)
    rospy.on_shutdown(stop)
    rospy.loginfo("quadrotor_teleop: %s -> %s (%s)", rospy.resolve_name("joy"), pub.resolved_name,
                  config.describe())
    rospy.spin()
