#!/usr/bin/env python3
"""Velocity streaming: the first Crazyflie flies two circles 1 m up by streaming world-frame
velocities (the circle's own velocity, a lead for the lag of the onboard velocity loop, and a pull
towards the point it should be at), then hands control back to the high-level commander and lands
with the others. Without the lead the pull, acting on a position that trails, widens the circle (by
a quarter at one lap in 5 s).

The firmware's Mellinger controller flies no velocity setpoints (it holds only a height and gets 0 m
from a velocity-world setpoint), so this script flies the Crazyflie on the PID controller and gives
it back the swarm file's Mellinger after landing."""
import numpy as np

from pycrazyswarm import *  # noqa: F401,F403

Z = 1.0
RATE_HZ = 30.0
RADIUS = 0.5
PERIOD = 10.0
LAPS = 2
K_POSITION = 1.0        # 1/s
VELOCITY_LAG = 0.2      # s, the onboard velocity loop's (PID controller) time constant, about


def circle(timeHelper, cf, center):
    start = timeHelper.time()
    omega = 2 * np.pi / PERIOD
    while not timeHelper.isShutdown():
        t = timeHelper.time() - start
        if t > LAPS * PERIOD:
            break
        desired = center + RADIUS * np.array([np.cos(omega * t), np.sin(omega * t), 0.0])
        velocity = RADIUS * omega * np.array([-np.sin(omega * t), np.cos(omega * t), 0.0])
        acceleration = -RADIUS * omega ** 2 * np.array([np.cos(omega * t), np.sin(omega * t), 0.0])
        lead = VELOCITY_LAG * acceleration
        cf.cmdVelocityWorld(velocity + lead + K_POSITION * (desired - cf.position()), yawRate=0)
        timeHelper.sleepForRate(RATE_HZ)


if __name__ == "__main__":
    swarm = Crazyswarm()            # noqa: F405
    timeHelper = swarm.timeHelper
    allcfs = swarm.allcfs
    cf = allcfs.crazyflies[0]
    cf.setParam("stabilizer/controller", 1)

    allcfs.takeoff(targetHeight=Z, duration=1.0 + Z)
    timeHelper.sleep(2.0 + Z)
    # the circle starts where the Crazyflie is: its centre RADIUS behind it on x
    circle(timeHelper, cf, np.array(cf.initialPosition) + np.array([-RADIUS, 0.0, Z]))

    cf.notifySetpointsStop()
    cf.goTo(np.array(cf.initialPosition) + np.array([0, 0, Z]), 0, 2.0)
    timeHelper.sleep(2.5)
    allcfs.land(targetHeight=0.03, duration=1.0 + Z)
    timeHelper.sleep(2.0 + Z)
    cf.setParam("stabilizer/controller", 2)
