"""The simulated Crazyflie world: fake Crazyradio, firmware protocol side, physics (no rospy)."""
