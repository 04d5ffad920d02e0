"""crazyflie_ros HEAD's ``execute_trajectory.py TRAJECTORY.csv``: streams a trajectory file (the
uav_trajectory CSV) to ``/crazyflie/cmd_full_state`` at 100 Hz from the moment it starts, its
position, velocity, acceleration, yaw and body rates, until the trajectory's end.

The file's positions are absolute (the onboard estimator's frame), so it should start where the
Crazyflie is (for example on the ground). At the end HEAD just stopped streaming; here a trajectory
that ends at most LANDED_Z above the ground is followed by ``cmd_stop``, and one that ends higher is
left to the server's supervision of setpoint silence (its descent), with a warning. Another
Crazyflie: remap the topic (``/crazyflie/cmd_full_state:=/cf1/cmd_full_state``). Times are ROS time.
"""
from __future__ import annotations

import argparse
import sys
from typing import List, Optional

import rospy
from std_msgs.msg import Empty

from crazyflie_demo.rosutil import yaw_to_quaternion
from crazyflie_driver.errors import TrajectoryError
from crazyflie_driver.msg import FullState
from crazyflie_driver.nodes.ros_signals import init_node, publish_unless_shutting_down, shutting_down
from uav_trajectory import Trajectory, TrajectoryOutput

RATE_HZ = 100.0
TOPIC = "/crazyflie/cmd_full_state"
STOP_TOPIC = "/crazyflie/cmd_stop"
LANDED_Z = 0.05        # m: a trajectory ending this low ends with cmd_stop
STOP_FLUSH_S = 0.5     # s (ROS time) the node stays after its cmd_stop, so the message leaves


def full_state(e: TrajectoryOutput, msg: FullState) -> FullState:
    """``msg`` filled with one evaluated point of the trajectory."""
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in e.pos)
    msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z = (float(v) for v in e.vel)
    msg.acc.x, msg.acc.y, msg.acc.z = (float(v) for v in e.acc)
    q = yaw_to_quaternion(float(e.yaw))
    msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z, msg.pose.orientation.w = q
    msg.twist.angular.x, msg.twist.angular.y, msg.twist.angular.z = (float(v) for v in e.omega)
    return msg


def parse(argv: List[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    parser.add_argument("trajectory", type=str, help="CSV file containing trajectory")
    return parser.parse_args(argv)


def main(argv: Optional[List[str]] = None) -> None:
    args = parse(rospy.myargv(sys.argv if argv is None else argv)[1:])
    try:
        traj = Trajectory().loadcsv(args.trajectory)
    except TrajectoryError as e:
        sys.exit("execute_trajectory.py: %s" % e)
    init_node("full_state")
    pub = rospy.Publisher(TOPIC, FullState, queue_size=1)
    stop_pub = rospy.Publisher(STOP_TOPIC, Empty, queue_size=1)
    rate = rospy.Rate(RATE_HZ)
    msg = FullState()
    msg.header.frame_id = "/world"
    start = rospy.Time.now()
    last = traj.eval(0.0)
    try:
        while not shutting_down():
            msg.header.seq += 1
            msg.header.stamp = rospy.Time.now()
            t = (msg.header.stamp - start).to_sec()
            if t > traj.duration:
                break
            last = traj.eval(t)
            publish_unless_shutting_down(pub, full_state(last, msg))
            rate.sleep()
        if shutting_down():
            return
        if float(last.pos[2]) <= LANDED_Z:
            publish_unless_shutting_down(stop_pub, Empty())
            rospy.sleep(STOP_FLUSH_S)
        else:
            rospy.logwarn("the trajectory ended %.2f m up; the Crazyflie is left to the server's setpoint-silence "
                          "supervision", float(last.pos[2]))
    except rospy.ROSInterruptException:
        pass
