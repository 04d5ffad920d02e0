#!/usr/bin/env python3
"""One Crazyflie after the other: each takes off and hovers until the operator's go-ahead, then
lands while the next one takes off."""
from pycrazyswarm import *  # noqa: F401,F403


def main():
    swarm = Crazyswarm()            # noqa: F405
    allcfs = swarm.allcfs
    for cf in allcfs.crazyflies:
        print("cf%d" % cf.id, flush=True)
        cf.takeoff(1.0, 2.5)
        print("press button to continue", flush=True)
        swarm.input.waitUntilButtonPressed()
        cf.land(0.04, 2.5)


if __name__ == "__main__":
    main()
