#!/usr/bin/env python3
from crazyflie_demo.publish_pose_teleop_node import main

main()
