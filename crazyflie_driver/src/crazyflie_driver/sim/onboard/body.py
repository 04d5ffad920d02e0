"""What the flight code reads of a vehicle's true motion: the room's body rows, seen through a Protocol.

The simulated firmware takes its attitude, and its estimator's inputs, from the true motion of each
body (``sim.room.physics.BodyStates``, one row per vehicle). The flight code names only the columns
it reads, so it needs nothing of the room that steps it.
"""
from __future__ import annotations

from typing import Protocol

import numpy as np


class BodyRows(Protocol):
    """The true motion of every vehicle body, one row per vehicle (frames as in ``sim.room.physics``)."""

    position: np.ndarray               # (N, 3) world frame, m
    velocity: np.ndarray               # (N, 3) world frame, m/s
    quaternion: np.ndarray             # (N, 4) x, y, z, w (body -> world)
    omega: np.ndarray                  # (N, 3) body frame, rad/s (what an ideal gyro reads)
    specific_force: np.ndarray         # (N, 3) body frame, m/s² (what an ideal accelerometer reads)
