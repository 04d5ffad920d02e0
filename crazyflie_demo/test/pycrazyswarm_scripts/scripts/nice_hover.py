#!/usr/bin/env python3
"""A tidy hover for the whole swarm: take off together, straighten up above each start, hold until
the operator's go-ahead, land together."""
import numpy as np

from pycrazyswarm import *  # noqa: F401,F403

Z = 1.0

if __name__ == "__main__":
    swarm = Crazyswarm()            # noqa: F405
    timeHelper = swarm.timeHelper
    allcfs = swarm.allcfs

    allcfs.takeoff(targetHeight=Z, duration=1.0 + Z)
    timeHelper.sleep(1.5 + Z)
    for cf in allcfs.crazyflies:
        cf.goTo(np.array(cf.initialPosition) + np.array([0, 0, Z]), 0, 1.0)

    print("press button to continue...", flush=True)
    swarm.input.waitUntilButtonPressed()

    allcfs.land(targetHeight=0.02, duration=1.0 + Z)
    timeHelper.sleep(1.0 + Z)
