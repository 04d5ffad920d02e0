"""Port 3 (RPYT setpoints) plus the stop and emergency-stop packets.

RPYT is ``[roll f32, pitch f32, yaw f32, thrust u16]`` on 3:0, raw wire values:
sign conventions (the firmware's inverted pitch and yaw rate) belong to the
caller. Thrust is clamped to 0..MAX_THRUST, as the firmware does; roll, pitch and
yaw are held to the widest range the firmware acts on (+-MAX_RATE_DEG_S), so no
value can overflow the packing. Callers that know the flight mode check tighter
ranges first (the server: :mod:`crazyflie_driver.server.setpoint`).
"""
from __future__ import annotations

import math
import numbers
import struct

from crazyflie_driver.crtp.firmware_limits import MAX_RATE_DEG_S, MAX_THRUST
from crazyflie_driver.crtp.packet import (
    PORT_COMMANDER,
    PORT_GENERIC_SETPOINT,
    PORT_LOCALIZATION,
    PORT_SUPERVISOR,
    CRTPPacket,
)

#: Protocol version from which the emergency stop lives on the supervisor port (9:1).
SUPERVISOR_FROM = 12
#: Protocol version from which port 7 (generic setpoints, with its "stop" type) exists.
GENERIC_SETPOINT_FROM = 3
ESTOP_COMMAND = 3
GENERIC_STOP = 0


_RPYT = struct.Struct("<fffH")


def _finite(name: str, value: float) -> float:
    """``value`` as a float; ValueError for anything that is not a finite real number."""
    kind = type(value)
    try:
        number = float(value) if kind is float or kind is int or isinstance(value, numbers.Real) else math.nan
    except OverflowError:
        number = math.nan
    if number - number != 0.0:          # NaN or infinite
        raise ValueError("setpoint %s must be a finite number, got %r" % (name, value))
    return number


def _rate(value: float) -> float:
    """Held to the widest range the firmware acts on."""
    return -MAX_RATE_DEG_S if value < -MAX_RATE_DEG_S else (MAX_RATE_DEG_S if value > MAX_RATE_DEG_S else value)


def rpyt_packet(roll: float, pitch: float, yawrate: float, thrust: float) -> CRTPPacket:
    """The 14-byte RPYT setpoint; ValueError for a value that is not a finite number."""
    kind = type(thrust)
    if not (type(roll) is float and type(pitch) is float and type(yawrate) is float
            and roll - roll == 0.0 and pitch - pitch == 0.0 and yawrate - yawrate == 0.0
            and ((kind is float and thrust - thrust == 0.0) or (kind is int and 0 <= thrust <= MAX_THRUST))):
        # anything but finite floats and a finite float or in-range int thrust: the general checks,
        # which name the value
        roll, pitch, yawrate = _finite("roll", roll), _finite("pitch", pitch), _finite("yaw rate", yawrate)
        thrust = _finite("thrust", thrust)
    thrust_u16 = int(0 if thrust < 0 else (MAX_THRUST if thrust > MAX_THRUST else thrust))
    return CRTPPacket(PORT_COMMANDER, 0, _RPYT.pack(_rate(roll), _rate(pitch), _rate(yawrate), thrust_u16))


def stop_packet(protocol_version: int) -> CRTPPacket:
    """Motors off: generic setpoint "stop" where port 7 exists, else an all-zero RPYT."""
    if protocol_version >= GENERIC_SETPOINT_FROM:
        return CRTPPacket(PORT_GENERIC_SETPOINT, 0, bytes([GENERIC_STOP]))
    return rpyt_packet(0.0, 0.0, 0.0, 0)


def emergency_stop_packet(protocol_version: int) -> CRTPPacket:
    """Supervisor 9:1 [3] on protocol 12 and later, else localization 6:1 [3]."""
    if protocol_version >= SUPERVISOR_FROM:
        return CRTPPacket(PORT_SUPERVISOR, 1, bytes([ESTOP_COMMAND]))
    return CRTPPacket(PORT_LOCALIZATION, 1, bytes([ESTOP_COMMAND]))


class Commander:
    """Sends setpoints over a link; each call is one radio round trip, True when acked."""

    def __init__(self, link) -> None:
        self.link = link
        self.protocol_version = -1

    def send_setpoint(self, roll: float, pitch: float, yawrate: float, thrust: float) -> bool:
        return self.link.send(rpyt_packet(roll, pitch, yawrate, thrust))

    def send_stop_setpoint(self) -> bool:
        return self.link.send(stop_packet(self.protocol_version))

    def send_emergency_stop(self) -> bool:
        return self.link.send(emergency_stop_packet(self.protocol_version))
