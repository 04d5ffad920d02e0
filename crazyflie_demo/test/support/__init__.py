"""What the rostests of crazyflie_demo share: the world probe, tracks and waits."""
