#!/usr/bin/env python3
"""Every Crazyflie of the swarm flies a figure-8, the Crazyswarm way: a template for your own scripts.

Written on the pycrazyswarm API, so it runs as a Crazyswarm script would:
    rosrun crazyflie_demo swarm_figure8.py --sim                   # starts (or joins) a simulated swarm
    roslaunch crazyflie_demo swarm.launch sim:=true n:=9 demo:=false &
    rosrun crazyflie_demo swarm_figure8.py                         # drives the running swarm
--swarm_file picks the Crazyflies (default: the package's config/swarm9.yaml), --height the hover
height. The figure-8 (trajectories/figure8.csv) is uploaded once to each Crazyflie, then one broadcast
starts it on all of them, relative to where each one is. Group mask 0 addresses every Crazyflie.
"""
import argparse
import os

import rospkg

import uav_trajectory
from pycrazyswarm import Crazyswarm

TRAJECTORY_ID = 1
TAKEOFF_S = 2.5
LAND_S = 2.5
SETTLE_S = 1.0


def main():
    package = rospkg.RosPack().get_path("crazyflie_demo")
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--swarm_file", default=os.path.join(package, "config", "swarm9.yaml"),
                        help="the Crazyflies to fly (a swarm file or Crazyswarm's crazyflies.yaml)")
    parser.add_argument("--height", type=float, default=1.0, help="hover height [m]")
    options, _ = parser.parse_known_args()

    swarm = Crazyswarm(crazyflies_yaml=options.swarm_file, parent_parser=parser)
    timeHelper, allcfs = swarm.timeHelper, swarm.allcfs
    figure8 = uav_trajectory.Trajectory()
    figure8.loadcsv(os.path.join(package, "trajectories", "figure8.csv"))
    for cf in allcfs.crazyflies:
        cf.uploadTrajectory(TRAJECTORY_ID, 0, figure8)

    allcfs.takeoff(targetHeight=options.height, duration=TAKEOFF_S)
    timeHelper.sleep(TAKEOFF_S + SETTLE_S)
    allcfs.startTrajectory(TRAJECTORY_ID)           # timescale 1, forwards, relative to each start
    timeHelper.sleep(figure8.duration + SETTLE_S)
    allcfs.land(targetHeight=0.04, duration=LAND_S)
    timeHelper.sleep(LAND_S + SETTLE_S)


if __name__ == "__main__":
    main()
