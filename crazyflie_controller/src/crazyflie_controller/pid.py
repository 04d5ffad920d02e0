"""One PID loop with output and integrator limits, timed by the caller's timestamps.

The position controller runs four of these. Two derivative modes exist:

* ``derivative="measurement"`` (default): D = kd · (target_rate − measurement_rate). A jump of the
  target (a new goal) never reaches the D term; a target that moves smoothly along a planned
  trajectory may pass its rate so the D term does not fight the planned motion.
* ``derivative="error"``: D = kd · Δerror / Δt, the textbook form the original controller used.
  After a reset the previous error counts as 0, so the first sample kicks (kept on purpose so
  benchmarks can reproduce the original behaviour).

The integral is the integral of the error (not of ki · error), clamped to
[integrator_min, integrator_max]; the I term is ki · integral. Time comes from the caller, so
the same code runs on ROS time, simulated time and in tests.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

DERIVATIVE_MODES = ("measurement", "error")


@dataclass(frozen=True)
class PidGains:
    """Gains and limits of one axis, named as in ``crazyflie2.yaml`` (``PIDs/<axis>/...``)."""

    kp: float
    kd: float
    ki: float
    min_output: float
    max_output: float
    integrator_min: float
    integrator_max: float

    def __post_init__(self) -> None:
        for name in ("kp", "kd", "ki", "min_output", "max_output", "integrator_min", "integrator_max"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or value != value or value in (float("inf"), float("-inf")):
                raise ValueError("PID gain %s must be a finite number, got %r" % (name, value))
        if self.min_output > self.max_output:
            raise ValueError("PID minOutput (%g) is above maxOutput (%g)" % (self.min_output, self.max_output))
        if self.integrator_min > self.integrator_max:
            raise ValueError("PID integratorMin (%g) is above integratorMax (%g)"
                             % (self.integrator_min, self.integrator_max))

    @classmethod
    def from_params(cls, params: dict, axis: str = "") -> PidGains:
        """Builds gains from a ``{kp, kd, ki, minOutput, maxOutput, integratorMin, integratorMax}`` dict."""
        names = {"kp": "kp", "kd": "kd", "ki": "ki", "min_output": "minOutput", "max_output": "maxOutput",
                 "integrator_min": "integratorMin", "integrator_max": "integratorMax"}
        values = {}
        for field_name, key in names.items():
            if key not in params:
                raise ValueError("PID %s: parameter %s is missing" % (axis or "?", key))
            try:
                values[field_name] = float(params[key])
            except (TypeError, ValueError):
                raise ValueError("PID %s: parameter %s must be a number, got %r"
                                 % (axis or "?", key, params[key])) from None
        try:
            return cls(**values)
        except ValueError as e:
            raise ValueError("PID %s: %s" % (axis or "?", e)) from e


def clamp(value: float, low: float, high: float) -> float:
    return low if value < low else high if value > high else value


class PID:
    """A PID loop; call :meth:`update` once per control cycle with a timestamp in seconds."""

    def __init__(self, gains: PidGains, derivative: str = "measurement", name: str = "") -> None:
        if derivative not in DERIVATIVE_MODES:
            raise ValueError("derivative mode must be one of %s, got %r" % (DERIVATIVE_MODES, derivative))
        self.gains = gains
        self.derivative = derivative
        self.name = name
        self.integral = 0.0
        self.last_output = 0.0
        self.last_terms = (0.0, 0.0, 0.0)  # (p, i, d) of the last update, for logs and tests
        self._prev_time: Optional[float] = None
        self._prev_error = 0.0
        self._prev_measurement: Optional[float] = None

    def reset(self, now: Optional[float] = None) -> None:
        """Forgets the integral and the derivative history; ``now`` starts the next dt."""
        self.integral = 0.0
        self.last_output = 0.0
        self.last_terms = (0.0, 0.0, 0.0)
        self._prev_time = now
        self._prev_error = 0.0
        self._prev_measurement = None

    def forget_derivative(self) -> None:
        """Drops the derivative history (after a gap in the measurements) but keeps the integral."""
        self._prev_time = None
        self._prev_measurement = None

    @property
    def i_term(self) -> float:
        return self.gains.ki * self.integral

    def set_i_term(self, value: float) -> None:
        """Preloads the integrator so that the I term equals ``value`` (within the integrator limits)."""
        if self.gains.ki == 0:
            self.integral = 0.0
            return
        g = self.gains
        self.integral = clamp(value / g.ki, g.integrator_min, g.integrator_max)

    def update(self, target: float, measurement: float, now: float, target_rate: float = 0.0,
               measurement_rate: Optional[float] = None, integrate: bool = True) -> float:
        """Returns the clamped output for this cycle.

        ``measurement_rate`` (e.g. a velocity estimate) replaces differencing the measurement in
        ``measurement`` mode. A timestamp that does not advance (or goes back) neither integrates
        nor differentiates; the previous dt is never reused. ``integrate=False`` holds the
        integral for this cycle (the caller's anti-windup decision).
        """
        g = self.gains
        error = target - measurement
        dt = None if self._prev_time is None else now - self._prev_time
        if dt is not None and dt <= 0.0:
            dt = None
        if dt is not None and integrate:
            self.integral = clamp(self.integral + error * dt, g.integrator_min, g.integrator_max)

        d = 0.0
        if self.derivative == "error":
            if dt is not None:
                d = g.kd * (error - self._prev_error) / dt
        else:
            rate = measurement_rate
            if rate is None and dt is not None and self._prev_measurement is not None:
                rate = (measurement - self._prev_measurement) / dt
            if rate is not None:
                d = g.kd * (target_rate - rate)
        p = g.kp * error
        i = g.ki * self.integral
        self.last_terms = (p, i, d)
        self._prev_error = error
        self._prev_measurement = measurement
        self._prev_time = now
        self.last_output = clamp(p + i + d, g.min_output, g.max_output)
        return self.last_output
