#!/usr/bin/env python3
"""A figure-8 from a CSV file, the way Crazyswarm's scripts fly one: upload to every Crazyflie, take
off together, go above the start, fly it forwards, then backwards, land."""
import numpy as np

import uav_trajectory
from pycrazyswarm import *  # noqa: F401,F403  (Crazyswarm's scripts import it this way)

if __name__ == "__main__":
    swarm = Crazyswarm()            # noqa: F405
    timeHelper = swarm.timeHelper
    allcfs = swarm.allcfs

    traj1 = uav_trajectory.Trajectory()
    traj1.loadcsv("figure8.csv")

    TIMESCALE = 1.0
    for cf in allcfs.crazyflies:
        cf.uploadTrajectory(0, 0, traj1)

    allcfs.takeoff(targetHeight=1.0, duration=2.0)
    timeHelper.sleep(2.5)
    for cf in allcfs.crazyflies:
        pos = np.array(cf.initialPosition) + np.array([0, 0, 1.0])
        cf.goTo(pos, 0, 2.0)
    timeHelper.sleep(2.5)

    allcfs.startTrajectory(0, timescale=TIMESCALE)
    timeHelper.sleep(traj1.duration * TIMESCALE + 2.0)
    allcfs.startTrajectory(0, timescale=TIMESCALE, reverse=True)
    timeHelper.sleep(traj1.duration * TIMESCALE + 2.0)

    allcfs.land(targetHeight=0.06, duration=2.0)
    timeHelper.sleep(3.0)
