"""The server's ROS-free core: workers, registry, log plan, cmd_vel mapping."""
