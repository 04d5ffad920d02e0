#!/usr/bin/env python3
"""Full-state streaming as Crazyswarm's users write it: take off with the high-level commander, then
stream the figure-8 from its CSV (position, velocity, acceleration, yaw, body rates) at 30 Hz, 0.5 m
above the take-off height, hand control back and land."""
import numpy as np

import uav_trajectory
from pycrazyswarm import Crazyswarm

RATE_HZ = 30.0
Z = 0.5


def stream(timeHelper, cf, path, rate, offset):
    traj = uav_trajectory.Trajectory()
    traj.loadcsv(path)
    start = timeHelper.time()
    while not timeHelper.isShutdown():
        t = timeHelper.time() - start
        if t > traj.duration:
            break
        e = traj.eval(t)
        cf.cmdFullState(e.pos + np.array(cf.initialPosition) + offset, e.vel, e.acc, e.yaw, e.omega)
        timeHelper.sleepForRate(rate)


if __name__ == "__main__":
    swarm = Crazyswarm()
    timeHelper = swarm.timeHelper
    cf = swarm.allcfs.crazyflies[0]

    cf.takeoff(targetHeight=Z, duration=Z + 1.0)
    timeHelper.sleep(Z + 2.0)
    stream(timeHelper, cf, "figure8.csv", RATE_HZ, offset=np.array([0, 0, Z]))
    cf.notifySetpointsStop()
    cf.land(targetHeight=0.03, duration=Z + 1.0)
    timeHelper.sleep(Z + 2.0)
