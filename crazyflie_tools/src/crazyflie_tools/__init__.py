"""crazyflie_tools Python package."""
