#!/usr/bin/env python3
from crazyflie_demo.position_demo import main

main()
