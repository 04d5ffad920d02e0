"""The setpoint a cmd_vel message asks for, as the values that go on the wire (port 3, RPYT).

Kept apart from the worker: the mapping (trims, pitch sign, thrust clamp) is a pure function
with its own tests.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

MAX_THRUST = 60000


@dataclass(frozen=True)
class Setpoint:
    """Wire values of a port-3 RPYT setpoint (angles in degrees, yaw rate in deg/s)."""

    roll: float
    pitch: float
    yawrate: float
    thrust: int


def setpoint_from_twist(linear_x: float, linear_y: float, linear_z: float, angular_z: float,
                        roll_trim: float = 0.0, pitch_trim: float = 0.0) -> Setpoint:
    """The original crazyflie_server's cmd_vel mapping.

    roll = linear.y + roll_trim; pitch = -(linear.x + pitch_trim); yaw rate = angular.z;
    thrust = linear.z clamped to 0..60000. Raises ValueError on NaN or infinity.
    """
    for label, v in (("linear.x", linear_x), ("linear.y", linear_y), ("linear.z", linear_z),
                     ("angular.z", angular_z)):
        if not math.isfinite(v):
            raise ValueError("cmd_vel %s is %r" % (label, v))
    thrust = int(min(max(linear_z, 0.0), float(MAX_THRUST)))
    return Setpoint(roll=linear_y + roll_trim, pitch=-(linear_x + pitch_trim),
                    yawrate=angular_z, thrust=thrust)
