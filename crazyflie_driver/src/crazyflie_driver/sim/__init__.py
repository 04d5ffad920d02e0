"""The simulated Crazyflie world (no rospy), one package per part it plays: ``onboard`` (flight
software), ``crtp`` (radio side), ``room`` (physics, sensors, motion capture, stepping), ``air``
(fake Crazyradio, media, UDP); ``world_server`` composes them."""
