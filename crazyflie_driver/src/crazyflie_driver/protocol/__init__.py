"""The Crazyflie object and one module per CRTP port."""
