#!/usr/bin/env python3
from crazyflie_demo.execute_trajectory import main

main()
