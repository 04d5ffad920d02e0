"""crazyflie_demo Python package."""
