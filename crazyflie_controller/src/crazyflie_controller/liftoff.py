"""Estimates the hover thrust from the take-off ramp: the thrust at the moment the vehicle left the ground.

The original preloads the Z integrator with the thrust reached when lift-off is *detected*
(5 cm up). Under a linear thrust ramp the climb grows with the cube of the time since lift-off,
so by then the ramp has added several thousand counts above hover (≈ 5 000 for a 32 g Crazyflie)
and that excess is what makes the vehicle overshoot. Here the cube root of the climb, which is
linear in time, is fitted by least squares over the poses seen during the climb; where the line
crosses zero is the lift-off time, and the ramp's thrust one motor lag earlier is the hover thrust.
"""
from __future__ import annotations

from typing import List, Optional, Tuple


class LiftoffEstimator:
    def __init__(self, min_climb: float = 0.005, min_samples: int = 3) -> None:
        self.min_climb = min_climb      # m: smaller climbs are lost in mocap noise
        self.min_samples = min_samples
        self._thrust: List[Tuple[float, float]] = []   # (time, commanded thrust from then on)
        self._climb: List[Tuple[float, float]] = []    # (pose stamp, height above start)

    def record_thrust(self, t: float, thrust: float) -> None:
        self._thrust.append((t, thrust))

    def record_climb(self, stamp: float, climb: float) -> None:
        if climb >= self.min_climb:
            self._climb.append((stamp, climb))

    def _fit(self) -> Optional[Tuple[float, float]]:
        """(lift-off time, slope of ∛climb over time) of the least-squares line, or None."""
        pts = self._climb
        if len(pts) < self.min_samples:
            return None
        ts = [t for t, _ in pts]
        cs = [c ** (1.0 / 3.0) for _, c in pts]
        n = float(len(pts))
        mt, mc = sum(ts) / n, sum(cs) / n
        var = sum((t - mt) ** 2 for t in ts)
        if var <= 0:
            return None
        slope = sum((t - mt) * (c - mc) for t, c in zip(ts, cs)) / var
        if slope <= 0:
            return None
        return mt - mc / slope, slope

    def liftoff_time(self) -> Optional[float]:
        fit = self._fit()
        return None if fit is None else fit[0]

    def thrust_gain(self, ramp_rate: float) -> Optional[float]:
        """Vertical acceleration per thrust count [m/s² per count] near hover, or None without a fit.

        The climb is G·rate·(t − t0)³/6 under a thrust ramp of ``ramp_rate`` counts/s, and the fit's
        slope is the cube root of G·rate/6.
        """
        fit = self._fit()
        if fit is None or not ramp_rate > 0:
            return None
        return 6.0 * fit[1] ** 3 / ramp_rate

    def thrust_at(self, t: float) -> Optional[float]:
        """The commanded ramp thrust at time ``t``, interpolated between control ticks."""
        pts = self._thrust
        if not pts or t < pts[0][0]:
            return None
        for (t1, u1), (t2, u2) in zip(pts, pts[1:]):
            if t1 <= t <= t2:
                return u1 if t2 == t1 else u1 + (u2 - u1) * (t - t1) / (t2 - t1)
        return pts[-1][1]

    def hover_thrust(self, fallback: float, lag: float = 0.0) -> float:
        """The thrust produced at lift-off, or ``fallback`` when the climb does not fit a ramp lift-off.

        ``lag``: how long the commanded thrust takes to become thrust (motor time constant and
        half a control period), so the command that lifted the vehicle is the one of t0 − lag.
        """
        t0 = self.liftoff_time()
        if t0 is None:
            return fallback
        thrust = self.thrust_at(t0 - lag)
        if thrust is None or thrust <= 0:
            return fallback
        return min(thrust, fallback)
