#!/usr/bin/env python3
"""The chapter's demo2.py: the second Crazyflie of multi_waypoint_vicon.launch."""
from demo import Demo

if __name__ == '__main__':
    demo = Demo(
        [
            # x,   y,    z,    yaw (rad), sleep (s)
            [0.0, -1.0, 0.5, 0, 2],
            [1.5, -1.0, 0.5, 0, 2],
            [-1.5, -1.0, 0.75, 0, 2],
            [-1.5, -1.5, 0.5, 0, 2],
            [0.0, -1.0, 0.5, 0, 0],
        ]
    )
    demo.run()
