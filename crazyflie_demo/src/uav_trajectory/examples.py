"""The example trajectory files (``crazyflie_demo/trajectories``), computed here, not copied.

``figure8``: the swarm demo's figure-8 (``crazyflie_demo.figure8``: 2 m × 1 m, 8 s from rest to
rest, 0.76 m/s mean and 1.48 m/s top speed, 16 degree-7 pieces with continuous jerk), relative to its
start at the origin, z and yaw 0: fly it with ``startTrajectory(relative=True)`` from a hover.
``takeoff``: straight up from the origin to ``height`` in ``duration`` s, from rest to rest (the one
degree-7 polynomial with zero velocity, acceleration and jerk at both ends), in two pieces.
``rosrun crazyflie_demo make_trajectories`` writes both.
"""
from __future__ import annotations

from typing import List

from crazyflie_demo.figure8 import DEGREE, figure8_pieces, hermite7
from crazyflie_driver.protocol.trajectory import Piece, make_piece
from uav_trajectory import Polynomial, Trajectory

TAKEOFF_HEIGHT_M = 1.0
TAKEOFF_DURATION_S = 3.0
TAKEOFF_PIECES = 2


def figure8() -> Trajectory:
    return Trajectory.from_pieces(figure8_pieces())


def _state(coefficients: List[float], t: float) -> List[float]:
    """Position and its first three derivatives of a polynomial at t."""
    p, out = Polynomial(coefficients), []
    for _ in range(4):
        out.append(p.eval(t))
        p = p.derivative()
    return out


def takeoff(height: float = TAKEOFF_HEIGHT_M, duration: float = TAKEOFF_DURATION_S,
            pieces: int = TAKEOFF_PIECES) -> Trajectory:
    whole = hermite7(duration, [0.0, 0.0, 0.0, 0.0], [height, 0.0, 0.0, 0.0])
    dt = duration / pieces
    zero = [0.0] * (DEGREE + 1)
    out: List[Piece] = []
    for i in range(pieces):
        z = hermite7(dt, _state(whole, i * dt), _state(whole, (i + 1) * dt))
        out.append(make_piece(dt, zero, zero, z, zero, index=i))
    return Trajectory.from_pieces(out)


EXAMPLES = {"figure8.csv": figure8, "takeoff.csv": takeoff}
