#!/usr/bin/env python3
"""Every Crazyflie of the swarm flies a figure-8, the Crazyswarm way: a template for your own scripts.

Needs crazyflie_server in swarm mode (it streams the motion capture to the Crazyflies), e.g.
    roslaunch crazyflie_demo swarm.launch sim:=true n:=9 demo:=false
    rosrun crazyflie_demo swarm_figure8.py _swarm_file:=$(rospack find crazyflie_demo)/config/swarm9.yaml
The trajectory is uploaded once to each Crazyflie, then one broadcast starts it on all of them,
relative to where each one is. Group mask 0 addresses every Crazyflie.
"""
import rospy

from crazyflie_demo.figure8 import figure8_pieces, trajectory_duration
from crazyflie_driver.msg import TrajectoryPolynomialPiece
from crazyflie_driver.nodes.ros_signals import init_node
from crazyflie_driver.server.swarm_config import load_swarm_file
from crazyflie_driver.srv import Land, StartTrajectory, Takeoff, UploadTrajectory

ALL = 0                 # group mask: every Crazyflie
HEIGHT = 1.0            # m
TRAJECTORY_ID = 1


def service(name, kind):
    rospy.wait_for_service(name, timeout=120.0)
    return rospy.ServiceProxy(name, kind)


def main():
    init_node("swarm_figure8")
    swarm = load_swarm_file(rospy.get_param("~swarm_file"))
    figure8 = figure8_pieces()
    pieces = [TrajectoryPolynomialPiece(p.x, p.y, p.z, p.yaw, rospy.Duration.from_sec(p.duration)) for p in figure8]
    for cf in swarm.crazyflies:
        service("/%s/upload_trajectory" % cf.name, UploadTrajectory)(TRAJECTORY_ID, 0, pieces)

    takeoff, land = service("/takeoff", Takeoff), service("/land", Land)
    start_trajectory = service("/start_trajectory", StartTrajectory)

    takeoff(ALL, HEIGHT, rospy.Duration(2.5))
    rospy.sleep(3.5)
    start_trajectory(ALL, TRAJECTORY_ID, 1.0, False, True)     # timescale 1, forwards, relative
    rospy.sleep(trajectory_duration(figure8) + 1.0)
    land(ALL, 0.0, rospy.Duration(2.5))
    rospy.sleep(3.0)


if __name__ == "__main__":
    main()
