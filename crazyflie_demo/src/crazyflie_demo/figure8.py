"""The swarm demo's figure-8 as poly4d pieces, computed here (no file of coefficients).

The curve is x = A·sin θ, y = B·sin 2θ in the plane of the start position, relative to it, flown
once from rest to rest: θ = 2π·s(t), where s rises from 0 to 1 with a speed profile that ramps up
with a smootherstep over ``ramp`` seconds, cruises, and ramps down the same way. Each piece is the
one degree-7 polynomial per axis that matches the curve's position, velocity, acceleration and
jerk at both of its ends (Hermite interpolation), so consecutive pieces join with continuous jerk
and the pieces stay within a fraction of a millimetre of the curve. With the defaults (2 m × 1 m,
8 s, 2 s ramps) the mean speed is 0.76 m/s and the top speed 1.48 m/s, the speeds of Crazyswarm's
figure-8.
"""
from __future__ import annotations

import math
from typing import List, Sequence, Tuple

from crazyflie_driver.protocol.trajectory import Piece, evaluate, make_piece

HALF_WIDTH_M = 1.0
HALF_HEIGHT_M = 0.5
DURATION_S = 8.0
RAMP_S = 2.0
PIECES = 16
DEGREE = 7


def _ramp(x: float) -> Tuple[float, float, float, float]:
    """The smootherstep speed profile at x in [0, 1]: its integral Q, value q, q' and q''."""
    return (x ** 6 - 3 * x ** 5 + 2.5 * x ** 4, 6 * x ** 5 - 15 * x ** 4 + 10 * x ** 3,
            30 * x ** 4 - 60 * x ** 3 + 30 * x ** 2, 120 * x ** 3 - 180 * x ** 2 + 60 * x)


def progress(t: float, duration: float = DURATION_S, ramp: float = RAMP_S) -> Tuple[float, float, float, float]:
    """s(t) in [0, 1] and its first three derivatives (1/s, 1/s², 1/s³)."""
    if not 0 < 2 * ramp <= duration:
        raise ValueError("the ramps (2 × %.2f s) must fit in the duration %.2f s" % (ramp, duration))
    total = duration - ramp                       # the integral of the speed profile
    t = min(max(t, 0.0), duration)
    if t < ramp:
        big, q, dq, ddq = _ramp(t / ramp)
        return ramp * big / total, q / total, dq / ramp / total, ddq / ramp ** 2 / total
    if t > duration - ramp:
        big, q, dq, ddq = _ramp((duration - t) / ramp)
        return 1.0 - ramp * big / total, q / total, -dq / ramp / total, ddq / ramp ** 2 / total
    return (0.5 * ramp + t - ramp) / total, 1.0 / total, 0.0, 0.0


def _sine_derivatives(amplitude: float, k: float, s: Sequence[float]) -> List[float]:
    """amplitude·sin(2πk·s(t)) and its first three time derivatives, from s and its derivatives."""
    w = 2 * math.pi * k
    th, th1, th2, th3 = (w * v for v in s)
    sn, cs = math.sin(th), math.cos(th)
    return [amplitude * sn, amplitude * cs * th1, amplitude * (-sn * th1 ** 2 + cs * th2),
            amplitude * (-cs * th1 ** 3 - 3 * sn * th1 * th2 + cs * th3)]


def curve(t: float, half_width: float = HALF_WIDTH_M, half_height: float = HALF_HEIGHT_M,
          duration: float = DURATION_S, ramp: float = RAMP_S) -> Tuple[List[float], List[float]]:
    """(x, ẋ, ẍ, x⃛) and (y, ẏ, ÿ, y⃛) of the figure-8 at t, relative to its start."""
    s = progress(t, duration, ramp)
    return _sine_derivatives(half_width, 1.0, s), _sine_derivatives(half_height, 2.0, s)


def hermite7(duration: float, start: Sequence[float], end: Sequence[float]) -> List[float]:
    """Coefficients (ascending powers of t) of the degree-7 polynomial with position, velocity,
    acceleration and jerk ``start`` at t = 0 and ``end`` at t = ``duration``."""
    import numpy as np

    def row(t: float, k: int) -> List[float]:
        return [math.factorial(n) / math.factorial(n - k) * t ** (n - k) if n >= k else 0.0
                for n in range(DEGREE + 1)]
    a = np.array([row(0.0, k) for k in range(4)] + [row(duration, k) for k in range(4)])
    return [float(c) for c in np.linalg.solve(a, np.array(list(start) + list(end), dtype=float))]


def figure8_pieces(half_width: float = HALF_WIDTH_M, half_height: float = HALF_HEIGHT_M,
                   duration: float = DURATION_S, ramp: float = RAMP_S, pieces: int = PIECES) -> List[Piece]:
    """The figure-8 as ``pieces`` poly4d pieces of equal length; z and yaw stay 0 (relative flight)."""
    if pieces < 1:
        raise ValueError("a trajectory needs at least one piece, got %d" % pieces)
    dt = duration / pieces
    zero = [0.0] * (DEGREE + 1)
    out = []
    for i in range(pieces):
        (x0, y0), (x1, y1) = (curve(i * dt, half_width, half_height, duration, ramp),
                              curve((i + 1) * dt, half_width, half_height, duration, ramp))
        out.append(make_piece(dt, hermite7(dt, x0, x1), hermite7(dt, y0, y1), zero, zero, index=i))
    return out


def trajectory_duration(pieces: Sequence[Piece]) -> float:
    return sum(p.duration for p in pieces)


def position_at(pieces: Sequence[Piece], t: float) -> Tuple[float, float, float]:
    """The planned (x, y, z) at t seconds after the start (held at the ends)."""
    t = max(0.0, t)
    for p in pieces:
        if t <= p.duration:
            return evaluate(p, t)[:3]
        t -= p.duration
    last = pieces[-1]
    return evaluate(last, last.duration)[:3]
