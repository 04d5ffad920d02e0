"""What the tests of crazyflie_driver share: doubles, the cflib find patch, rostest helpers."""
