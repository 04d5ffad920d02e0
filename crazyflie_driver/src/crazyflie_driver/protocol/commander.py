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
from typing import Callable

from crazyflie_driver.crtp.firmware_limits import MAX_RATE_DEG_S, MAX_THRUST
from crazyflie_driver.crtp.packet import (
    PORT_COMMANDER,
    PORT_GENERIC_SETPOINT,
    PORT_LOCALIZATION,
    PORT_SUPERVISOR,
    CRTPPacket,
    make_header,
)

#: Protocol version from which the emergency stop lives on the supervisor port (9:1).
SUPERVISOR_FROM = 12
#: Protocol version from which port 7 (generic setpoints, with its "stop" type) exists.
GENERIC_SETPOINT_FROM = 3
ESTOP_COMMAND = 3
GENERIC_STOP = 0


_RPYT = struct.Struct("<BfffH")       # header byte, roll, pitch, yaw rate, thrust
#: Header byte of an RPYT setpoint (port 3, channel 0, link bits set).
RPYT_HEADER = make_header(PORT_COMMANDER, 0)


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


def rpyt_bytes(roll: float, pitch: float, yawrate: float, thrust: float) -> bytes:
    """The RPYT setpoint as a raw packet: header byte (3:0) and 14-byte payload; ValueError for a value
    that is not a finite number."""
    if (type(roll) is float and type(pitch) is float and type(yawrate) is float and type(thrust) is int
            and -MAX_RATE_DEG_S <= roll <= MAX_RATE_DEG_S and -MAX_RATE_DEG_S <= pitch <= MAX_RATE_DEG_S
            and -MAX_RATE_DEG_S <= yawrate <= MAX_RATE_DEG_S and 0 <= thrust <= MAX_THRUST):
        # the common case: float rates within range (so finite), an int thrust within range: as given
        return _RPYT.pack(RPYT_HEADER, roll, pitch, yawrate, thrust)
    # anything else: the general checks, which name the value, then the clamps
    roll, pitch, yawrate = _finite("roll", roll), _finite("pitch", pitch), _finite("yaw rate", yawrate)
    thrust = _finite("thrust", thrust)
    thrust_u16 = int(0 if thrust < 0 else (MAX_THRUST if thrust > MAX_THRUST else thrust))
    return _RPYT.pack(RPYT_HEADER, _rate(roll), _rate(pitch), _rate(yawrate), thrust_u16)


def rpyt_packet(roll: float, pitch: float, yawrate: float, thrust: float) -> CRTPPacket:
    """The 14-byte RPYT setpoint; ValueError for a value that is not a finite number."""
    return CRTPPacket(PORT_COMMANDER, 0, rpyt_bytes(roll, pitch, yawrate, thrust)[1:])


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
        # A link that takes raw packets (``RadioLink.send_bytes``) is handed the setpoint's bytes as
        # built: no CRTPPacket to build and serialise again for each of 100 setpoints a second.
        send_bytes = getattr(link, "send_bytes", None)
        self._send_raw: Callable[[bytes], bool] = send_bytes if send_bytes is not None else self._send_packet

    def _send_packet(self, raw: bytes) -> bool:
        return self.link.send(CRTPPacket.from_bytes(raw))

    def send_setpoint(self, roll: float, pitch: float, yawrate: float, thrust: float) -> bool:
        return self._send_raw(rpyt_bytes(roll, pitch, yawrate, thrust))

    def send_stop_setpoint(self) -> bool:
        return self.link.send(stop_packet(self.protocol_version))

    def send_emergency_stop(self) -> bool:
        return self.link.send(emergency_stop_packet(self.protocol_version))
