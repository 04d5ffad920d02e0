"""Stand-in for Crazyswarm's SWIG-wrapped firmware module (``pycrazyswarm.cfsim.cffirmware``).

Crazyswarm's scripts import it (some only for the name ``firm``); the import succeeds so they run
unchanged, and any attribute raises ``NotSupported`` with what to use instead: the firmware here runs
inside the simulated world (``--sim`` or ``swarm.launch sim:=true``), reached through the Crazyflie API.
"""
from __future__ import annotations

from crazyflie_driver.errors import NotSupported


def __getattr__(name: str):
    if name.startswith("__"):
        raise AttributeError(name)
    raise NotSupported("pycrazyswarm.cfsim.cffirmware.%s: Crazyswarm's in-process firmware simulator is not part of "
                       "this stack; the simulated firmware runs in the simulated world (--sim or swarm.launch "
                       "sim:=true): fly it through Crazyflie/CrazyflieServer calls, and evaluate trajectories "
                       "with uav_trajectory" % name)
