#!/usr/bin/env python3
"""Waypoints of the first Crazyflie in multi_waypoint_vicon.launch: [x, y, z, yaw_deg, sleep_s]."""
from crazyflie_demo.demo_node import run
run([
    [0.0, 0.0, 0.5, 0, 2],
    [0.5, 0.0, 0.5, 0, 2],
    [0.5, 0.5, 0.7, 0, 2],
    [0.0, 0.5, 0.7, 90, 2],
    [0.0, 0.0, 0.5, 0, 2],
])
