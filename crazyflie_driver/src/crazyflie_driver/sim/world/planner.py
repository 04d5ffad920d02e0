"""The high-level commander's planner: polynomial pieces, online plans and their evaluation.

Pure functions and a small per-vehicle plan object. Every online plan (takeoff, land, go_to) is one
degree-7 piece per axis (x, y, z, yaw) over its duration, fixing position, velocity and
acceleration at both ends and the jerk to zero at both ends, as the firmware's planner does; an
uploaded trajectory is a list of such pieces (poly4d). Facts in docs/simulation.md ("High-level
commander").
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import List, Optional, Sequence, Tuple

import numpy as np

DEGREE = 7
N_COEFFS = DEGREE + 1
AXES = 4                                   # x, y, z, yaw

IDLE, FLYING, LANDING, DISABLED = 0, 1, 3, 4


@dataclass
class Piece:
    """One polynomial piece: coefficients (4, 8) in ascending powers of t (s), and its duration (s)."""

    duration: float
    coeffs: np.ndarray


@dataclass
class Evaluation:
    pos: np.ndarray            # (3,) m
    vel: np.ndarray            # (3,) m/s
    acc: np.ndarray            # (3,) m/s²
    yaw: float                 # rad
    yaw_rate: float            # rad/s


def _basis(t: float, derivative: int) -> np.ndarray:
    """Row of d^k/dt^k [1, t, t², …, t^7] at t."""
    row = np.zeros(N_COEFFS)
    for n in range(derivative, N_COEFFS):
        row[n] = math.factorial(n) / math.factorial(n - derivative) * t ** (n - derivative)
    return row


def poly7_nojerk(duration: float, start: Sequence[float], end: Sequence[float]) -> np.ndarray:
    """Coefficients of the degree-7 polynomial with (p, v, a) = ``start`` at 0 and ``end`` at ``duration``
    and zero jerk at both ends. ``duration`` <= 0 gives the constant end position."""
    if not duration > 0:
        c = np.zeros(N_COEFFS)
        c[0] = end[0]
        return c
    if not math.isfinite(duration):
        return np.full(N_COEFFS, np.nan)          # what the firmware's float arithmetic gives
    a = np.array([_basis(0.0, k) for k in range(4)] + [_basis(duration, k) for k in range(4)])
    b = np.array([start[0], start[1], start[2], 0.0, end[0], end[1], end[2], 0.0])
    return np.linalg.solve(a, b)


def evaluate(piece: Piece, t: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity and acceleration (each (4,): x, y, z, yaw) of a piece at t (clamped)."""
    t = min(max(t, 0.0), piece.duration)
    powers = t ** np.arange(N_COEFFS)
    c = piece.coeffs
    n = np.arange(N_COEFFS)
    p = c @ powers
    v = c[:, 1:] @ (n[1:] * powers[:-1])
    a = c[:, 2:] @ (n[2:] * (n[2:] - 1) * powers[:-2])
    return p, v, a


def wrap_angle(rad: float) -> float:
    """The angle in [-pi, pi)."""
    return (rad + math.pi) % (2.0 * math.pi) - math.pi


def shortest_angle(from_rad: float, to_rad: float) -> float:
    return (to_rad - from_rad + math.pi) % (2.0 * math.pi) - math.pi


def online_piece(duration: float, start: Evaluation, goal_pos: Sequence[float], goal_yaw: float,
                 goal_vel: Sequence[float] = (0.0, 0.0, 0.0), goal_yaw_rate: float = 0.0) -> Piece:
    """One piece from ``start`` (its velocity and acceleration kept) to the goal; yaw the short way."""
    yaw_goal = start.yaw + shortest_angle(start.yaw, goal_yaw)
    coeffs = np.zeros((AXES, N_COEFFS))
    for k in range(3):
        coeffs[k] = poly7_nojerk(duration, (start.pos[k], start.vel[k], start.acc[k]),
                                 (goal_pos[k], goal_vel[k], 0.0))
    coeffs[3] = poly7_nojerk(duration, (start.yaw, start.yaw_rate, 0.0), (yaw_goal, goal_yaw_rate, 0.0))
    return Piece(max(duration, 0.0), coeffs)


@dataclass
class Plan:
    """What the planner of one vehicle follows: pieces played from ``t_begin`` (world time)."""

    state: int = IDLE
    pieces: List[Piece] = field(default_factory=list)
    t_begin: float = 0.0
    timescale: float = 1.0
    reversed: bool = False
    shift: np.ndarray = field(default_factory=lambda: np.zeros(4))     # added to x, y, z, yaw

    @property
    def duration(self) -> float:
        return sum(p.duration for p in self.pieces) * self.timescale

    def evaluate(self, now: float) -> Optional[Evaluation]:
        """The plan at world time ``now``; after its end, the end point at rest. None without pieces."""
        if not self.pieces:
            return None
        total = sum(p.duration for p in self.pieces)
        t = (now - self.t_begin) / self.timescale
        ended = t >= total
        t = min(max(t, 0.0), total)
        if self.reversed:
            t = total - t
        for piece in self.pieces:
            if t <= piece.duration or piece is self.pieces[-1]:
                break
            t -= piece.duration
        p, v, a = evaluate(piece, t)
        scale = -1.0 if self.reversed else 1.0
        v = v * scale / self.timescale
        a = a / (self.timescale ** 2)
        if ended:
            v, a = np.zeros(4), np.zeros(4)
        p = p + self.shift
        return Evaluation(p[:3].copy(), v[:3].copy(), a[:3].copy(), float(p[3]), float(v[3]))

    def finished(self, now: float) -> bool:
        return bool(self.pieces) and now - self.t_begin >= self.duration


def figure_eight(half_width: float, half_height: float, period: float, n_pieces: int, z: float) -> List[Piece]:
    """A figure-8 at height ``z`` as poly4d pieces: x = w·sin(ωt), y = h·sin(2ωt), one period, starting
    and ending at (0, 0, z) in motion; each piece matches the curve's position, velocity and
    acceleration at its ends (for tests and benchmarks of trajectory tracking)."""
    omega = 2.0 * math.pi / period
    dt = period / n_pieces

    def state(t: float, amplitude: float, w: float) -> Tuple[float, float, float]:
        return (amplitude * math.sin(w * t), amplitude * w * math.cos(w * t), -amplitude * w * w * math.sin(w * t))

    pieces = []
    for k in range(n_pieces):
        t0, t1 = k * dt, (k + 1) * dt
        coeffs = np.zeros((AXES, N_COEFFS))
        coeffs[0] = poly7_nojerk(dt, state(t0, half_width, omega), state(t1, half_width, omega))
        coeffs[1] = poly7_nojerk(dt, state(t0, half_height, 2 * omega), state(t1, half_height, 2 * omega))
        coeffs[2, 0] = z
        pieces.append(Piece(dt, coeffs))
    return pieces
