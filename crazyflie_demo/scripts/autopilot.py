#!/usr/bin/env python3
from crazyflie_demo.autopilot_node import main

main()
