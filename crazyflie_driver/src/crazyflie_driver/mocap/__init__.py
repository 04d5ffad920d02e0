"""Motion capture: VRPN client and helpers (no rospy outside *_node modules)."""
