"""rospy nodes of crazyflie_driver; each module has a main()."""
