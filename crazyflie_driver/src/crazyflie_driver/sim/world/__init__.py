"""What the simulated world plays: physics, stabilizer, sensors, battery, motion capture."""
