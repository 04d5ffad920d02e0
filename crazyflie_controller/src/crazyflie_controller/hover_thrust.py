"""Refines the hover thrust from the first seconds of closed-loop hover after the take-off.

The lift-off estimate (``liftoff``) is within one or two hundred counts of the hover thrust, and
the Z integrator (ki 3500 in the chapter's gains) corrects such an error only through the Z loop's
slow, lightly damped mode (period ≈ 7 s, time constant ≈ 3 s): the vehicle sagged ≈ 3 cm and
took ≈ 15 s to settle. Over a short stretch of flight the height obeys

    z(τ) = z0 + v0·τ + G·∬ (u(t − lag) − H)

with u the commanded thrust, ``lag`` the command-to-thrust delay and G the vertical acceleration
per count (from the lift-off climb: ``LiftoffEstimator.thrust_gain``). With G known, the height is
linear in the unknowns (z0, v0, H), so a least-squares fit over all the poses of the window gives
the hover thrust H without differentiating the noisy mocap positions.
"""
from __future__ import annotations

from typing import List, Optional, Tuple


def _solve3(a: List[List[float]], b: List[float]) -> Optional[List[float]]:
    """Solves the 3×3 system a·x = b (Cramer's rule); None when it is singular."""
    def det(m: List[List[float]]) -> float:
        return (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))
    d = det(a)
    scale = max(abs(v) for row in a for v in row) ** 3
    if scale == 0 or abs(d) <= 1e-12 * scale:
        return None
    out = []
    for col in range(3):
        m = [[b[r] if c == col else a[r][c] for c in range(3)] for r in range(3)]
        out.append(det(m) / d)
    return out


class HoverThrustFit:
    """Collects commanded thrusts and measured heights from ``start``; :meth:`estimate` fits H."""

    def __init__(self, start: float, gain: float, lag: float) -> None:
        if not gain > 0:
            raise ValueError("hover thrust fit needs a positive thrust gain (m/s² per count), got %r" % (gain,))
        self.start = float(start)
        self.gain = float(gain)
        self.lag = float(lag)
        self._commands: List[Tuple[float, float]] = []   # (time, commanded thrust from then on)
        self._heights: List[Tuple[float, float]] = []    # (pose stamp, z)

    def record_command(self, t: float, thrust: float) -> None:
        if not self._commands or t > self._commands[-1][0]:
            self._commands.append((t, thrust))

    def record_height(self, stamp: float, z: float) -> None:
        if stamp >= self.start + self.lag and (not self._heights or stamp > self._heights[-1][0]):
            self._heights.append((stamp, z))

    def _thrust(self, t: float) -> float:
        """The command of ``lag`` before ``t``, interpolated between control ticks (as the lift-off
        estimate reads the ramp: ``lag`` includes half a control period)."""
        t -= self.lag
        cmds = self._commands
        if t <= cmds[0][0]:
            return cmds[0][1]
        for (t1, u1), (t2, u2) in zip(cmds, cmds[1:]):
            if t1 <= t <= t2:
                return u1 + (u2 - u1) * (t - t1) / (t2 - t1)
        return cmds[-1][1]

    def estimate(self, min_samples: int = 20) -> Optional[float]:
        """Least-squares hover thrust [counts], or None with too few samples or no fit."""
        pts = self._heights
        if len(pts) < min_samples or not self._commands or self._commands[0][0] > pts[0][0] - self.lag:
            return None
        g = self.gain
        t0 = pts[0][0]
        # Double integral of the thrust from t0, on the pose stamps (trapezoids between stamps).
        w, rate, prev_t, prev_u = 0.0, 0.0, t0, self._thrust(t0)
        rows = []
        for t, z in pts:
            if t > prev_t:
                u = self._thrust(t)
                new_rate = rate + 0.5 * (prev_u + u) * (t - prev_t)
                w += 0.5 * (rate + new_rate) * (t - prev_t)
                rate, prev_t, prev_u = new_rate, t, u
            tau = t - t0
            rows.append(((1.0, tau, -0.5 * g * tau * tau), z - g * w))
        ata = [[sum(r[0][i] * r[0][j] for r in rows) for j in range(3)] for i in range(3)]
        atb = [sum(r[0][i] * r[1] for r in rows) for i in range(3)]
        x = _solve3(ata, atb)
        return None if x is None else x[2]
