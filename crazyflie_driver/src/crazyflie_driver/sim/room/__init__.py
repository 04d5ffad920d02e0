"""The room the simulated Crazyflies fly in: rigid-body physics, sensors, battery, motion capture, and
the world that steps them (and each vehicle's onboard flight code) tick by tick."""
