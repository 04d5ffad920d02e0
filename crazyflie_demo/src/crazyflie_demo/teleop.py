"""Joystick axes -> cmd_vel, with hector_quadrotor_teleop's parameters, without ROS.

Each output (linear.x, linear.y, linear.z, angular.z) takes one Joy axis, given 1-based so that a
negative number can invert it (``-3`` is axes[2] negated; 0 disables the output), times a maximum.
An axis the Joy message does not have gives 0.

For the Crazyflie the output goes to crazyflie_server's cmd_vel, so the units are not velocities:
linear.x / linear.y are pitch / roll in degrees, linear.z is thrust (0..60000) and angular.z the yaw
rate in deg/s. The thrust stick is self-centring, and the chapter's launch files map it as
``z_velocity_max * axis`` (centre = 0, full up = 60000); the lower half would ask for negative
thrust, which the server clamps to 0. ``z_min`` (optional, set to 0 by our xbox360/ps3 launch
files) makes that explicit here, so cmd_vel itself never carries a negative thrust: the lower half
of the stick, the centre and a released stick all mean motors off, full up is ``z_velocity_max``.
Mapping the whole stick travel to 0..max instead was rejected: a released stick would then mean
half thrust.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Optional, Sequence

# hector_quadrotor_teleop's defaults
DEFAULT_AXES = {"x_axis": 4, "y_axis": 3, "z_axis": 2, "yaw_axis": 1}
DEFAULT_MAXIMA = {"x_velocity_max": 2.0, "y_velocity_max": 2.0, "z_velocity_max": 2.0,
                  "yaw_velocity_max": math.radians(90.0)}


class TeleopConfigError(ValueError):
    """A teleop parameter has a value that cannot be used."""


@dataclass(frozen=True)
class AxisMapping:
    """One output: 1-based joystick axis (negative inverts, 0 disables) times ``maximum``."""
    axis: int
    maximum: float

    def value(self, axes: Sequence[float]) -> float:
        if self.axis == 0:
            return 0.0
        index = abs(self.axis) - 1
        if index >= len(axes):
            return 0.0
        sign = -1.0 if self.axis < 0 else 1.0
        return sign * float(axes[index]) * self.maximum


@dataclass(frozen=True)
class TwistCommand:
    """The four Twist fields the teleop sets (the others stay 0)."""
    linear_x: float = 0.0
    linear_y: float = 0.0
    linear_z: float = 0.0
    angular_z: float = 0.0


@dataclass(frozen=True)
class TeleopConfig:
    x: AxisMapping = AxisMapping(DEFAULT_AXES["x_axis"], DEFAULT_MAXIMA["x_velocity_max"])
    y: AxisMapping = AxisMapping(DEFAULT_AXES["y_axis"], DEFAULT_MAXIMA["y_velocity_max"])
    z: AxisMapping = AxisMapping(DEFAULT_AXES["z_axis"], DEFAULT_MAXIMA["z_velocity_max"])
    yaw: AxisMapping = AxisMapping(DEFAULT_AXES["yaw_axis"], DEFAULT_MAXIMA["yaw_velocity_max"])
    z_min: Optional[float] = None      # lower bound of linear.z (None: no bound, as hector)

    @classmethod
    def from_params(cls, get: Callable[[str, Any], Any]) -> TeleopConfig:
        """Build from a parameter getter ``get(name, default)`` such as ``rospy.get_param('~' + name)``."""
        def axis(name: str) -> int:
            value = get(name, DEFAULT_AXES[name])
            whole = isinstance(value, int) or (isinstance(value, float) and value.is_integer())
            if isinstance(value, bool) or not whole:
                raise TeleopConfigError("parameter %s must be a whole axis number "
                                        "(1-based, negative inverts, 0 disables), got %r" % (name, value))
            return int(value)

        def number(name: str, default: Optional[float]) -> Optional[float]:
            value = get(name, default)
            if value is None and default is None:
                return None
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise TeleopConfigError("parameter %s must be a finite number, got %r" % (name, value))
            return float(value)

        return cls(x=AxisMapping(axis("x_axis"), number("x_velocity_max", DEFAULT_MAXIMA["x_velocity_max"])),
                   y=AxisMapping(axis("y_axis"), number("y_velocity_max", DEFAULT_MAXIMA["y_velocity_max"])),
                   z=AxisMapping(axis("z_axis"), number("z_velocity_max", DEFAULT_MAXIMA["z_velocity_max"])),
                   yaw=AxisMapping(axis("yaw_axis"),
                                   number("yaw_velocity_max", DEFAULT_MAXIMA["yaw_velocity_max"])),
                   z_min=number("z_min", None))

    def command(self, axes: Sequence[float]) -> TwistCommand:
        """The Twist for one Joy message's axes."""
        z = self.z.value(axes)
        if self.z_min is not None:
            z = max(self.z_min, z)
        return TwistCommand(linear_x=self.x.value(axes), linear_y=self.y.value(axes),
                            linear_z=z, angular_z=self.yaw.value(axes))

    def describe(self) -> str:
        parts = ["%s=axis %d x %g" % (n, m.axis, m.maximum)
                 for n, m in (("x", self.x), ("y", self.y), ("z", self.z), ("yaw", self.yaw))]
        if self.z_min is not None:
            parts.append("z_min=%g" % self.z_min)
        return ", ".join(parts)
