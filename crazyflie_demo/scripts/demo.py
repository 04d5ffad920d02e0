#!/usr/bin/env python3
"""Flies the waypoints given in the private parameter ~waypoints."""
from crazyflie_demo.demo_node import main
main()
