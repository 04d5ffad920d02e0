"""The setpoint a cmd_vel message asks for, as the values that go on the wire (port 3, RPYT).

Kept apart from the worker: the mapping (trims, pitch sign, ranges) is a pure function with its
own tests. This is the one place a cmd_vel's numbers are checked: a field that is not a finite
number refuses the whole message (the last good setpoint stays), a finite one outside what the
firmware accepts (see :mod:`crazyflie_driver.crtp.firmware_limits`) is held to the limit and noted.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, List, Mapping, Tuple

from crazyflie_driver.crtp.firmware_limits import MAX_ANGLE_DEG, MAX_RATE_DEG_S, MAX_THRUST

#: ``flightmode.stabModeRoll`` / ``stabModePitch`` value meaning "rate mode": the field is deg/s.
STAB_MODE_RATE = 0


@dataclass(frozen=True)
class Setpoint:
    """Wire values of a port-3 RPYT setpoint (angles in degrees, yaw rate in deg/s).

    ``notes`` names the fields that were held to their limit (for the log), empty when none was.
    """

    roll: float
    pitch: float
    yawrate: float
    thrust: int
    notes: Tuple[str, ...] = field(default=(), compare=False)


@dataclass(frozen=True)
class SetpointLimits:
    """Largest magnitude of each RPYT field: deg in angle mode, deg/s in rate mode (and for yaw)."""

    roll: float = MAX_ANGLE_DEG
    pitch: float = MAX_ANGLE_DEG
    yawrate: float = MAX_RATE_DEG_S


def limits_for_modes(params: Mapping[str, Any]) -> SetpointLimits:
    """The limits for the Crazyflie's flight modes (``flightmode.stabModeRoll/Pitch``; angle if unknown)."""
    def limit(name: str) -> float:
        return MAX_RATE_DEG_S if params.get(name) == STAB_MODE_RATE else MAX_ANGLE_DEG
    return SetpointLimits(roll=limit("flightmode.stabModeRoll"), pitch=limit("flightmode.stabModePitch"))


def _finite(value: Any) -> bool:
    try:
        return not isinstance(value, bool) and math.isfinite(value)
    except (TypeError, OverflowError):
        return False


def check_trim(name: str, value: Any) -> float:
    """A roll or pitch trim [deg] fit to add to every setpoint; ValueError naming it otherwise."""
    if not _finite(value):
        raise ValueError("%s must be a finite number of degrees, got %r" % (name, value))
    if abs(value) > MAX_ANGLE_DEG:
        raise ValueError("%s %r deg is outside -%g..%g deg (a trim is a small angle)"
                         % (name, value, MAX_ANGLE_DEG, MAX_ANGLE_DEG))
    return float(value)


def _held(label: str, value: float, limit: float, unit: str, notes: List[str]) -> float:
    if -limit <= value <= limit:
        return value
    held = math.copysign(limit, value)
    notes.append("%s %r %s is outside -%g..%g %s: sent as %g" % (label, value, unit, limit, limit, unit, held))
    return held


def setpoint_from_twist(linear_x: float, linear_y: float, linear_z: float, angular_z: float,
                        roll_trim: float = 0.0, pitch_trim: float = 0.0,
                        limits: SetpointLimits = SetpointLimits()) -> Setpoint:
    """The original crazyflie_server's cmd_vel mapping, held to what the firmware accepts.

    roll = linear.y + roll_trim; pitch = -(linear.x + pitch_trim); yaw rate = angular.z;
    thrust = linear.z clamped to 0..MAX_THRUST (as the original did, silently). Roll, pitch and
    yaw rate beyond ``limits`` are held to the limit and named in ``notes``. Raises ValueError
    naming the field when one is NaN or infinite.
    """
    fields = (("linear.x", linear_x), ("linear.y", linear_y), ("linear.z", linear_z),
              ("angular.z", angular_z), ("roll_trim", roll_trim), ("pitch_trim", pitch_trim))
    for label, v in fields:
        if not _finite(v):
            raise ValueError("cmd_vel %s is %r, not a finite number: message ignored" % (label, v))
    linear_x, linear_y, linear_z, angular_z, roll_trim, pitch_trim = (float(v) for _, v in fields)
    notes: List[str] = []
    roll = _held("roll (linear.y + roll_trim)", linear_y + roll_trim, limits.roll,
                 "deg/s" if limits.roll == MAX_RATE_DEG_S else "deg", notes)
    pitch = _held("pitch (-(linear.x + pitch_trim))", -(linear_x + pitch_trim), limits.pitch,
                  "deg/s" if limits.pitch == MAX_RATE_DEG_S else "deg", notes)
    yawrate = _held("yaw rate (angular.z)", angular_z, limits.yawrate, "deg/s", notes)
    thrust = int(min(max(linear_z, 0.0), float(MAX_THRUST)))
    return Setpoint(roll=roll, pitch=pitch, yawrate=yawrate, thrust=thrust, notes=tuple(notes))
