"""What the controller tests share: a small quadrotor model of our own, and flights against the
project's simulated world (also used by the benchmarks)."""
