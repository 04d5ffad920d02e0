"""crazyflie_controller Python package."""
