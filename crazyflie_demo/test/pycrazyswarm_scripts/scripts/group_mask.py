#!/usr/bin/env python3
"""Group masks as Crazyswarm's users use them: cf1 in group 1, cf2 in group 2; each broadcast takeoff
and goTo reaches its group only, the operator's go-ahead in between, one land for all."""
from pycrazyswarm import Crazyswarm

if __name__ == "__main__":
    swarm = Crazyswarm()
    timeHelper, allcfs = swarm.timeHelper, swarm.allcfs
    cf1, cf2 = allcfs.crazyfliesById[1], allcfs.crazyfliesById[2]
    cf1.setGroupMask(1)
    cf2.setGroupMask(2)

    allcfs.takeoff(targetHeight=0.5, duration=2.0, groupMask=1)
    timeHelper.sleep(2.5)
    allcfs.takeoff(targetHeight=1.0, duration=2.0, groupMask=2)
    timeHelper.sleep(2.5)
    swarm.input.waitUntilButtonPressed()
    allcfs.goTo([0.5, 0.0, 0.0], 0.0, 2.0, groupMask=1)
    timeHelper.sleep(3.0)
    allcfs.land(targetHeight=0.03, duration=2.0)
    timeHelper.sleep(3.0)
    for cf in allcfs.crazyflies:
        cf.setGroupMask(0)
