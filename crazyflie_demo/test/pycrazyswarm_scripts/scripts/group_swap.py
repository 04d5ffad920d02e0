#!/usr/bin/env python3
"""Two groups swap places and back with broadcast commands: cf1 in group 1, cf2 in group 2. Each
group steps aside to its own lane (1 m apart), flies along it to the other's place, steps back in,
then the same way home; one take-off and one landing for all."""
import pycrazyswarm.cfsim.cffirmware as firm  # noqa: F401  (Crazyswarm's swap scripts import it)
from pycrazyswarm import *  # noqa: F401,F403

LEG = 3.0
STEP = 2.0


def swap(timeHelper, allcfs, distance):
    allcfs.goTo([0.5, 0.0, 0.0], 0, STEP, groupMask=1)
    allcfs.goTo([-0.5, 0.0, 0.0], 0, STEP, groupMask=2)
    timeHelper.sleep(STEP + 0.5)
    allcfs.goTo([0.0, distance, 0.0], 0, LEG, groupMask=1)
    allcfs.goTo([0.0, -distance, 0.0], 0, LEG, groupMask=2)
    timeHelper.sleep(LEG + 0.5)
    allcfs.goTo([-0.5, 0.0, 0.0], 0, STEP, groupMask=1)
    allcfs.goTo([0.5, 0.0, 0.0], 0, STEP, groupMask=2)
    timeHelper.sleep(STEP + 1.0)


if __name__ == "__main__":
    swarm = Crazyswarm()            # noqa: F405
    timeHelper = swarm.timeHelper
    allcfs = swarm.allcfs
    cf1, cf2 = allcfs.crazyfliesById[1], allcfs.crazyfliesById[2]
    cf1.setGroupMask(1)
    cf2.setGroupMask(2)
    d = cf2.initialPosition[1] - cf1.initialPosition[1]

    allcfs.takeoff(targetHeight=1.0, duration=2.0)
    timeHelper.sleep(2.5)
    swap(timeHelper, allcfs, d)
    print("swapped", flush=True)
    swap(timeHelper, allcfs, -d)

    allcfs.land(targetHeight=0.03, duration=2.0)
    timeHelper.sleep(3.0)
    for cf in allcfs.crazyflies:
        cf.setGroupMask(0)
