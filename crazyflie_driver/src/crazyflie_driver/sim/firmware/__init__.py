"""The simulated Crazyflie's protocol side: link layer, TOCs, ports."""
