"""Crazyswarm's ``pycrazyswarm`` scripting API on this stack: ``from pycrazyswarm import Crazyswarm``.

``swarm = Crazyswarm()`` reads Crazyswarm's options (``--sim`` flies our simulated world) and the
Crazyflies of ``../launch/crazyflies.yaml``; ``swarm.timeHelper``, ``swarm.allcfs`` (swarm-wide
commands, ``crazyflies``, ``crazyfliesById``) and each ``Crazyflie`` take Crazyswarm's arguments,
defaults and units. docs/coming_from_crazyswarm.md lists every interface and how ours compares.
"""
from pycrazyswarm.crazyswarm_py import Crazyswarm

__all__ = ["Crazyswarm"]
