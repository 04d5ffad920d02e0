#!/usr/bin/env python3
from crazyflie_demo.external_position_node import main

main()
