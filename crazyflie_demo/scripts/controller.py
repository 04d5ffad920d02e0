#!/usr/bin/env python3
from crazyflie_demo.joystick_controller_node import main

main()
