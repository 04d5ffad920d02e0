"""Piecewise-polynomial trajectories in the CSV form Crazyswarm's ``uav_trajectory`` reads, without ROS.

A file has one header line, then one row per piece: ``duration, x^0..x^7, y^0..y^7, z^0..z^7,
yaw^0..yaw^7`` (seconds; metres and radians; ascending powers of the time since the piece began).
Further columns (e.g. a trailing comma) are ignored, as Crazyswarm's reader ignores them.
``Trajectory().loadcsv(path)`` reads one; ``eval(t)`` gives the flat outputs and what follows from
them (velocity, acceleration, body rates), ``pieces()`` the checked pieces the high-level commander
takes (``crazyflie_driver.protocol.trajectory.Piece``) and ``savecsv`` writes the same format.
The same attribute names as Crazyswarm's module (``polynomials``, each with ``duration``, ``px.p``,
``py.p``, ``pz.p``, ``pyaw.p``) keep scripts that walk the pieces themselves working.
"""
from __future__ import annotations

import csv
import math
from typing import Iterable, List, Optional, Sequence

import numpy as np

from crazyflie_driver.errors import TrajectoryError
from crazyflie_driver.protocol.trajectory import COEFFICIENTS, Piece, make_piece

GRAVITY = 9.81          # m/s², as Crazyswarm's uav_trajectory uses for the body rates
COLUMNS = 1 + 4 * COEFFICIENTS
HEADER = ["duration"] + ["%s^%d" % (axis, k) for axis in ("x", "y", "z", "yaw") for k in range(COEFFICIENTS)]
#: Coefficients below this are written as 0: a fit's rounding noise, not a motion.
ROUNDING_NOISE = 1e-12
#: Times this far past the end still evaluate (the end point): float sums of piece durations.
END_SLACK_S = 1e-9


class Polynomial:
    """One axis of a piece: coefficients ``p`` in ascending powers of t."""

    def __init__(self, p: Sequence[float]) -> None:
        self.p = np.asarray(p, dtype=float)

    def eval(self, t: float) -> float:
        value = 0.0
        for c in reversed(self.p):          # Horner
            value = value * t + c
        return float(value)

    def derivative(self) -> Polynomial:
        return Polynomial([k * c for k, c in enumerate(self.p)][1:] or [0.0])


class TrajectoryOutput:
    """What a trajectory gives at one instant: pos (m), vel (m/s), acc (m/s²), omega (rad/s, body
    frame), yaw (rad)."""

    def __init__(self, pos, vel, acc, omega, yaw: float) -> None:
        self.pos, self.vel, self.acc, self.omega, self.yaw = pos, vel, acc, omega, yaw

    def __repr__(self) -> str:
        return "TrajectoryOutput(pos=%s, vel=%s, acc=%s, omega=%s, yaw=%.4f)" % (
            self.pos.tolist(), self.vel.tolist(), self.acc.tolist(), self.omega.tolist(), self.yaw)


class Polynomial4D:
    """One piece: ``duration`` (s) and a polynomial per axis ``px``, ``py``, ``pz``, ``pyaw``."""

    def __init__(self, duration: float, px, py, pz, pyaw) -> None:
        self.duration = float(duration)
        self.px, self.py, self.pz, self.pyaw = (Polynomial(c) for c in (px, py, pz, pyaw))

    def derivative(self) -> Polynomial4D:
        return Polynomial4D(self.duration, *(a.derivative().p for a in (self.px, self.py, self.pz, self.pyaw)))

    def eval(self, t: float) -> TrajectoryOutput:
        """The flat outputs at ``t`` s into the piece, and the body rates they imply for a
        quadrotor (differential flatness: thrust along acc + g, the jerk turning it)."""
        d = [self]
        for _ in range(3):
            d.append(d[-1].derivative())
        axes = lambda q: np.array([q.px.eval(t), q.py.eval(t), q.pz.eval(t)])    # noqa: E731
        pos, vel, acc, jerk = (axes(q) for q in d)
        yaw, yaw_rate = self.pyaw.eval(t), d[1].pyaw.eval(t)
        thrust = acc + np.array([0.0, 0.0, GRAVITY])
        norm = float(np.linalg.norm(thrust))
        if norm < 1e-9:
            raise TrajectoryError("at t = %.3f s the acceleration cancels gravity (free fall): the body rates are "
                                  "undefined there" % t)
        z_body = thrust / norm
        heading = np.array([math.cos(yaw), math.sin(yaw), 0.0])
        y_body = np.cross(z_body, heading)
        y_body /= np.linalg.norm(y_body)
        x_body = np.cross(y_body, z_body)
        h = (jerk - np.dot(jerk, z_body) * z_body) / norm
        omega = np.array([-np.dot(h, y_body), np.dot(h, x_body), z_body[2] * yaw_rate])
        return TrajectoryOutput(pos, vel, acc, omega, yaw)


class Trajectory:
    """A sequence of pieces flown one after the other; ``duration`` is their sum (s)."""

    def __init__(self, polynomials: Optional[Iterable[Polynomial4D]] = None) -> None:
        self.polynomials: List[Polynomial4D] = list(polynomials) if polynomials is not None else []
        self.duration: float = sum(p.duration for p in self.polynomials)

    def n_pieces(self) -> int:
        return len(self.polynomials)

    def loadcsv(self, filename: str) -> Trajectory:
        """Read ``filename`` (header line, then a row per piece); every fault names the row."""
        try:
            with open(filename, newline="") as f:
                rows = list(csv.reader(f))
        except OSError as e:
            raise TrajectoryError("trajectory file %s cannot be read: %s" % (filename, e.strerror or e)) from None
        self._load_rows(rows, filename)
        return self

    def _load_rows(self, rows: List[List[str]], source: str) -> None:
        if not rows:
            raise TrajectoryError("%s is empty; a trajectory file has a header line, then one row per piece" % source)
        pieces = []
        for line, row in enumerate(rows[1:], start=2):
            cells = [c.strip() for c in row]
            if not any(cells):
                continue
            if len(cells) < COLUMNS or not all(cells[:COLUMNS]):
                raise TrajectoryError("%s:%d: %d values; a piece needs %d (duration, then 8 coefficients for each of "
                                      "x, y, z, yaw)" % (source, line, sum(1 for c in cells if c), COLUMNS))
            try:
                values = [float(c) for c in cells[:COLUMNS]]
            except ValueError as e:
                raise TrajectoryError("%s:%d: %s" % (source, line, e)) from None
            try:
                make_piece(values[0], values[1:9], values[9:17], values[17:25], values[25:33], index=line)
            except TrajectoryError as e:
                raise TrajectoryError("%s:%d: %s" % (source, line, str(e).split(": ", 1)[-1])) from None
            pieces.append(Polynomial4D(values[0], values[1:9], values[9:17], values[17:25], values[25:33]))
        if not pieces:
            raise TrajectoryError("%s has no pieces after its header line" % source)
        self.polynomials = pieces
        self.duration = sum(p.duration for p in pieces)

    def savecsv(self, filename: str) -> None:
        """Write the pieces in the format ``loadcsv`` reads."""
        with open(filename, "w", newline="") as f:
            w = csv.writer(f, lineterminator="\n")
            w.writerow(HEADER)
            for p in self.polynomials:
                w.writerow(["%.9g" % p.duration] + ["%.9g" % (c if abs(c) > ROUNDING_NOISE else 0.0)
                                                    for a in (p.px, p.py, p.pz, p.pyaw) for c in a.p])

    def eval(self, t: float) -> TrajectoryOutput:
        """The state ``t`` s after the start (0 <= t <= duration)."""
        if not self.polynomials:
            raise TrajectoryError("the trajectory has no pieces: loadcsv a file first")
        if not (0.0 <= t <= self.duration + END_SLACK_S):
            raise TrajectoryError("t = %r s is outside the trajectory (0 .. %.3f s)" % (t, self.duration))
        start = 0.0
        for p in self.polynomials:
            if t <= start + p.duration:
                return p.eval(max(0.0, t - start))
            start += p.duration
        last = self.polynomials[-1]
        return last.eval(last.duration)

    def pieces(self) -> List[Piece]:
        """The pieces as the high-level commander's upload takes them (checked)."""
        return [make_piece(p.duration, p.px.p.tolist(), p.py.p.tolist(), p.pz.p.tolist(), p.pyaw.p.tolist(), index=i)
                for i, p in enumerate(self.polynomials)]

    @classmethod
    def from_pieces(cls, pieces: Iterable[Piece]) -> Trajectory:
        return cls(Polynomial4D(p.duration, p.x, p.y, p.z, p.yaw) for p in pieces)
