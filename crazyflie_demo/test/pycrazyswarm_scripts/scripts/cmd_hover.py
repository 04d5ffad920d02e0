#!/usr/bin/env python3
"""Hover setpoints (Crazyswarm2's cmdHover): the first Crazyflie takes off to 0.5 m, climbs to 0.8 m
on streamed hover setpoints (their height is absolute), then flies a 0.5 m square by its own frame
alone: four times forward at 0.25 m/s for 2 s and a quarter turn left at 45 deg/s. Each side goes
where the Crazyflie faces. Then the high-level commander takes it back over its start and lands it.

The firmware's Mellinger controller flies no velocities (it holds only the height), so this script
flies the Crazyflie on the PID controller and gives it back the swarm file's Mellinger after landing."""
import numpy as np

from pycrazyswarm import *  # noqa: F401,F403

TAKEOFF_Z = 0.5
HOVER_Z = 0.8
RATE_HZ = 30.0
FORWARD = 0.25          # m/s in the Crazyflie's own x
SIDE_S = 2.0
YAW_RATE = 45.0         # deg/s, counterclockwise


def stream(timeHelper, cf, seconds, vx=0.0, yawRate=0.0):
    start = timeHelper.time()
    while not timeHelper.isShutdown() and timeHelper.time() - start < seconds:
        cf.cmdHover(vx, 0.0, yawRate, HOVER_Z)
        timeHelper.sleepForRate(RATE_HZ)


if __name__ == "__main__":
    swarm = Crazyswarm()            # noqa: F405
    timeHelper = swarm.timeHelper
    allcfs = swarm.allcfs
    cf = allcfs.crazyflies[0]
    cf.setParam("stabilizer/controller", 1)

    cf.takeoff(targetHeight=TAKEOFF_Z, duration=2.0)
    timeHelper.sleep(2.5)
    stream(timeHelper, cf, 2.0)                         # up to HOVER_Z
    for _ in range(4):
        stream(timeHelper, cf, SIDE_S, vx=FORWARD)
        stream(timeHelper, cf, 1.0)
        stream(timeHelper, cf, 90.0 / YAW_RATE, yawRate=YAW_RATE)
        stream(timeHelper, cf, 0.5)

    cf.notifySetpointsStop()
    cf.goTo(np.array(cf.initialPosition) + np.array([0.0, 0.0, HOVER_Z]), 0.0, 2.0)
    timeHelper.sleep(2.5)
    cf.land(targetHeight=0.03, duration=2.0)
    timeHelper.sleep(3.0)
    cf.setParam("stabilizer/controller", 2)
