#!/usr/bin/env python3
from crazyflie_demo.hover_demo import main

main()
