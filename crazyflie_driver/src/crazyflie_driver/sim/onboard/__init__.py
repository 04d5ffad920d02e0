"""The simulated Crazyflie's onboard flight software: stabilizer, estimator, controllers, planner,
high-level commander and supervisor, all vehicles at once (numpy rows)."""
