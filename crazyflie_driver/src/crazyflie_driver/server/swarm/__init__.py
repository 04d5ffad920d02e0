"""Swarm mode's ROS-free core: the swarm file and options, broadcasts, motion capture, the watch and its policy.

The per-Crazyflie path (worker, registry, safety, onboard commands) sits in ``server`` beside this
package and never imports it; the swarm builds on that path, not the other way round.
"""
