#!/usr/bin/env python3
from crazyflie_demo.external_position_node import main_position_vrpn

main_position_vrpn()
