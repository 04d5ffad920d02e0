"""crazyflie_driver: a ROS-free CRTP library for Crazyflies, plus the ROS nodes.

Everything importable from this package except ``crazyflie_driver.nodes`` and
``crazyflie_driver.mocap.*_node`` works without rospy.
"""
