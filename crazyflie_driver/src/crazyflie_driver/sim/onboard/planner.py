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
from typing import List, Optional, Tuple

import numpy as np

from crazyflie_driver.sim.vehicle_rows import Vector

DEGREE = 7
N_COEFFS = DEGREE + 1
AXES = 4                                   # x, y, z, yaw

IDLE, FLYING, LANDING, DISABLED = 0, 1, 3, 4
GRAVITY = 9.81                             # m/s², the planner's value for the body-rate feed-forward


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
    yaw_rate: float            # rad/s: the body z rate (the yaw derivative times the body z axis' z)
    omega_xy: Tuple[float, float] = (0.0, 0.0)     # rad/s: body x and y rates the plan asks for


def _basis(t: float, derivative: int) -> np.ndarray:
    """Row of d^k/dt^k [1, t, t², …, t^7] at t."""
    row = np.zeros(N_COEFFS)
    for n in range(derivative, N_COEFFS):
        row[n] = math.factorial(n) / math.factorial(n - derivative) * t ** (n - derivative)
    return row


def poly7_nojerk(duration: float, start: Vector, end: Vector) -> np.ndarray:
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


_N = np.arange(N_COEFFS)


def evaluate(piece: Piece, t: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity and acceleration (each (4,): x, y, z, yaw) of a piece at t (clamped)."""
    p, v, a, _ = evaluate_with_jerk(piece, t)
    return p, v, a


def evaluate_with_jerk(piece: Piece, t: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``evaluate`` and the third derivative (4,)."""
    t = min(max(t, 0.0), piece.duration)
    powers = t ** _N
    c = piece.coeffs
    n = _N
    p = c @ powers
    v = c[:, 1:] @ (n[1:] * powers[:-1])
    a = c[:, 2:] @ (n[2:] * (n[2:] - 1) * powers[:-2])
    j = c[:, 3:] @ (n[3:] * (n[3:] - 1) * (n[3:] - 2) * powers[:-3])
    return p, v, a, j


def body_rates(acc: Vector, jerk: Vector, yaw: float, yaw_rate: float) -> Tuple[float, float, float]:
    """The body rates (rad/s) of a differentially flat quadrotor following the plan (Mellinger & Kumar
    2011): the body z axis along acc + g, the jerk's part across it over the thrust per mass gives the
    x/y rates; the z rate is the yaw derivative times the body z axis' vertical component."""
    tx, ty, tz = float(acc[0]), float(acc[1]), float(acc[2]) + GRAVITY
    norm = math.sqrt(tx * tx + ty * ty + tz * tz)
    zx, zy, zz = tx / norm, ty / norm, tz / norm
    cy, sy = math.cos(yaw), math.sin(yaw)
    # y_body = normalize(z_body x (cos yaw, sin yaw, 0)); x_body = y_body x z_body
    yx, yy, yz = -zz * sy, zz * cy, zx * sy - zy * cy
    yn = math.sqrt(yx * yx + yy * yy + yz * yz)
    yx, yy, yz = yx / yn, yy / yn, yz / yn
    xx, xy, xz = yy * zz - yz * zy, yz * zx - yx * zz, yx * zy - yy * zx
    jx, jy, jz = float(jerk[0]), float(jerk[1]), float(jerk[2])
    along = jx * zx + jy * zy + jz * zz
    hx, hy, hz = (jx - along * zx) / norm, (jy - along * zy) / norm, (jz - along * zz) / norm
    return -(hx * yx + hy * yy + hz * yz), hx * xx + hy * xy + hz * xz, zz * yaw_rate


def normalize_radians(rad: float) -> float:
    """The firmware's angle normalisation: a truncating remainder after adding pi with the angle's sign,
    so positive angles land in [-pi, pi) and negative ones in (-pi, pi]."""
    signed_pi = math.copysign(math.pi, rad)
    return math.fmod(rad + signed_pi, 2.0 * math.pi) - signed_pi


def shortest_angle(from_rad: float, to_rad: float) -> float:
    return (to_rad - from_rad + math.pi) % (2.0 * math.pi) - math.pi


def yaw_turn(start_yaw: float, goal_yaw: float) -> Tuple[float, float]:
    """(start yaw normalised, the shortest signed turn to the goal): both ends of an online plan's yaw."""
    start = normalize_radians(start_yaw)
    return start, shortest_angle(start, normalize_radians(goal_yaw))


def online_piece(duration: float, start: Evaluation, goal_pos: Vector, goal_yaw: float,
                 goal_vel: Vector = (0.0, 0.0, 0.0), goal_yaw_rate: float = 0.0) -> Piece:
    """One piece from ``start`` (its velocity, acceleration and yaw rate kept) to the goal. The yaw
    starts from the start yaw normalised to about [-pi, pi] and turns the short way."""
    yaw0, turn = yaw_turn(start.yaw, goal_yaw)
    coeffs = np.zeros((AXES, N_COEFFS))
    for k in range(3):
        coeffs[k] = poly7_nojerk(duration, (start.pos[k], start.vel[k], start.acc[k]),
                                 (goal_pos[k], goal_vel[k], 0.0))
    coeffs[3] = poly7_nojerk(duration, (yaw0, start.yaw_rate, 0.0), (yaw0 + turn, goal_yaw_rate, 0.0))
    return Piece(max(duration, 0.0), coeffs)


@dataclass
class Plan:
    """What the planner of one vehicle follows: pieces played from ``t_begin`` (world time)."""

    state: int = IDLE
    pieces: List[Piece] = field(default_factory=list)
    t_begin: float = 0.0
    timescale: float = 1.0
    reversed: bool = False
    shift: np.ndarray = field(default_factory=lambda: np.zeros(3))     # m, added to x, y, z
    rotation: float = 0.0      # rad: a forward plan is turned about the world z axis by this, then shifted

    def shifted_to(self, start: Evaluation, relative_yaw: bool) -> None:
        """Relative start: the shift that moves the plan's first point to ``start``; with
        ``relative_yaw`` also the rotation by the shortest angle from the plan's first yaw to the
        start yaw. As the firmware does, the rotation turns the plan about the world origin and the
        shift is taken from the unrotated first point (the two agree when the plan starts above the
        origin), and only a forward plan is rotated."""
        self.shift, self.rotation = np.zeros(3), 0.0
        first = self.evaluate(self.t_begin)
        assert first is not None, "a plan shifted before it has pieces"
        self.shift = np.asarray(start.pos, dtype=float) - first.pos
        if relative_yaw:
            self.rotation = shortest_angle(normalize_radians(first.yaw), normalize_radians(start.yaw))

    @property
    def duration(self) -> float:
        return sum(p.duration for p in self.pieces) * self.timescale

    def evaluate(self, now: float) -> Optional[Evaluation]:
        """The plan at world time ``now``; after its end, the end point at rest. None without pieces."""
        if not self.pieces:
            return None
        total = sum(p.duration for p in self.pieces)
        t = (now - self.t_begin) / self.timescale
        ended = t > total                  # at the very end: still the last piece, as the firmware
        t = min(max(t, 0.0), total)
        if self.reversed:
            t = total - t
        for piece in self.pieces:
            if t <= piece.duration or piece is self.pieces[-1]:
                break
            t -= piece.duration
        p, v, a, j = evaluate_with_jerk(piece, t)
        if ended:
            rates = (0.0, 0.0, 0.0)
            v, a = np.zeros(4), np.zeros(4)
        else:
            scale = -1.0 if self.reversed else 1.0
            v = v * scale / self.timescale
            a = a / (self.timescale ** 2)
            j = j * scale / (self.timescale ** 3)
            rates = body_rates(a, j, float(p[3]), float(v[3]))
        pos, vel, acc, yaw = p[:3], v[:3], a[:3], float(p[3])
        if self.rotation and not self.reversed:
            angle = normalize_radians(self.rotation)
            c, s = math.cos(angle), math.sin(angle)
            turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            pos, vel, acc = turn @ pos, turn @ vel, turn @ acc
            yaw += angle
        return Evaluation(pos + self.shift, vel.copy(), acc.copy(), yaw, rates[2], (rates[0], rates[1]))

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
