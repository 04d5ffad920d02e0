#!/usr/bin/env python3
"""Timed waypoints from a CSV (agent id, x, y, z in m, arrival time in s): every Crazyflie goes to its
first waypoint after take-off, then leaves each waypoint so that it reaches the next one at its
arrival time; land when the last one is reached."""
import numpy as np

from pycrazyswarm import *  # noqa: F401,F403


def load(path):
    rows = np.loadtxt(path, skiprows=1, delimiter=",", ndmin=2)
    legs = []                       # (arrival, agent, position, duration)
    previous = {}
    for row in rows[np.lexsort((rows[:, 4], rows[:, 0]))]:
        agent, arrival = int(row[0]), float(row[4])
        legs.append((arrival, agent, row[1:4], arrival - previous.get(agent, 0.0)))
        previous[agent] = arrival
    legs.sort(key=lambda leg: leg[0])
    return legs


if __name__ == "__main__":
    legs = load("waypoints.csv")
    print(legs, flush=True)

    swarm = Crazyswarm()            # noqa: F405
    timeHelper = swarm.timeHelper
    allcfs = swarm.allcfs

    allcfs.takeoff(targetHeight=1.0, duration=2.0)
    timeHelper.sleep(2.0)
    now = 0.0
    for arrival, agent, pos, duration in legs:
        cf = allcfs.crazyfliesById[agent]
        if arrival == 0:
            cf.goTo(pos, 0, 2.0)
        elif duration > 0:
            # each leg starts when the agent's previous waypoint is due
            start = arrival - duration
            if start > now:
                timeHelper.sleep(start - now)
                now = start
            cf.goTo(pos, 0, duration)
    timeHelper.sleep(max(leg[0] for leg in legs) - now + 1.0)

    allcfs.land(targetHeight=0.02, duration=2.0)
    timeHelper.sleep(2.0)
