"""Crazyswarm's ``pycrazyswarm.cfsim``: its kinematic simulator, which ran a SWIG build of its firmware
fork's planner and controllers in the script's process. Here ``--sim`` flies our simulated world
instead (a separate process that answers the real radio protocol), so there is nothing to import from
it. Scripts that import ``cffirmware`` without using it keep working; any use raises ``NotSupported``.
"""
