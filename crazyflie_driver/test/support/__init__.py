"""What the tests of every package share: doubles, the cflib find patch, rostest and flight helpers."""
