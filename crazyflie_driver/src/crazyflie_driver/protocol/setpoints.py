"""Port 7 generic setpoints (channel 0) and the notify-setpoints-stop meta command (channel 1).

Every builder is pure: values in, one packet out, CommandValueError for a value that cannot go on
the wire. Yaw rates are given with the sign the current firmware uses (types 8 and 10); for
firmware before protocol 9 the legacy types 1 and 5 are sent with the rate negated, because that
firmware negates it again. Layouts are in docs/protocol.md.
"""
from __future__ import annotations

import struct
from typing import Sequence

from crazyflie_driver.crtp.packet import PORT_GENERIC_SETPOINT, CRTPPacket
from crazyflie_driver.crtp.quaternion import compress_quaternion
from crazyflie_driver.errors import CommandValueError, NotSupported
from crazyflie_driver.protocol.checks import finite, milli_int16
from crazyflie_driver.protocol.commander import GENERIC_SETPOINT_FROM, stop_packet

CH_SETPOINT = 0
CH_META = 1

TYPE_STOP = 0
TYPE_VELOCITY_WORLD_LEGACY = 1
TYPE_HOVER_LEGACY = 5
TYPE_FULL_STATE = 6
TYPE_POSITION = 7
TYPE_VELOCITY_WORLD = 8
TYPE_HOVER = 10
META_NOTIFY_SETPOINTS_STOP = 0

#: Protocol version from which types 8/9/10 (yaw rate not negated by the firmware) exist.
UNNEGATED_YAW_FROM = 9
_U32_MAX = 0xFFFFFFFF


def _require_generic(protocol_version: int) -> None:
    if protocol_version < GENERIC_SETPOINT_FROM:
        raise NotSupported("generic setpoints (port 7) need protocol version %d or later (firmware 2017.04+); "
                           "this Crazyflie speaks %d: update its firmware" % (GENERIC_SETPOINT_FROM,
                                                                             protocol_version))


def _floats(kind: int, names: Sequence[str], values: Sequence[float]) -> CRTPPacket:
    numbers = [finite(n, v) for n, v in zip(names, values)]
    return CRTPPacket(PORT_GENERIC_SETPOINT, CH_SETPOINT, struct.pack("<B4f", kind, *numbers))


def position_packet(x: float, y: float, z: float, yaw_deg: float) -> CRTPPacket:
    """Absolute position (m) and yaw (degrees), type 7."""
    return _floats(TYPE_POSITION, ("x", "y", "z", "yaw"), (x, y, z, yaw_deg))


def velocity_world_packet(vx: float, vy: float, vz: float, yawrate_deg: float,
                          protocol_version: int) -> CRTPPacket:
    """World-frame velocity (m/s) and yaw rate (deg/s): type 8, or legacy type 1 before protocol 9."""
    _require_generic(protocol_version)
    names = ("vx", "vy", "vz", "yaw rate")
    if protocol_version < UNNEGATED_YAW_FROM:
        return _floats(TYPE_VELOCITY_WORLD_LEGACY, names, (vx, vy, vz, -finite("yaw rate", yawrate_deg)))
    return _floats(TYPE_VELOCITY_WORLD, names, (vx, vy, vz, yawrate_deg))


def hover_packet(vx: float, vy: float, yawrate_deg: float, z: float, protocol_version: int) -> CRTPPacket:
    """Body-frame velocity (m/s), yaw rate (deg/s) and absolute height (m): type 10, or 5 before protocol 9."""
    _require_generic(protocol_version)
    names = ("vx", "vy", "yaw rate", "z")
    if protocol_version < UNNEGATED_YAW_FROM:
        return _floats(TYPE_HOVER_LEGACY, names, (vx, vy, -finite("yaw rate", yawrate_deg), z))
    return _floats(TYPE_HOVER, names, (vx, vy, yawrate_deg, z))


def full_state_packet(position: Sequence[float], velocity: Sequence[float], acceleration: Sequence[float],
                      quaternion: Sequence[float], body_rates: Sequence[float]) -> CRTPPacket:
    """Type 6: position (m), velocity (m/s), acceleration (m/s^2) in mm units as int16, the
    orientation (qx, qy, qz, qw) compressed to 32 bits, body rates (rad/s) as int16 mrad/s."""
    fields = []
    for label, vector in (("position", position), ("velocity", velocity), ("acceleration", acceleration),
                          ("body rate", body_rates)):
        if len(vector) != 3:
            raise CommandValueError("full-state %s needs 3 components, got %d" % (label, len(vector)))
        fields.append([milli_int16("%s %s" % (label, axis), v) for axis, v in zip("xyz", vector)])
    for i, c in enumerate(quaternion):
        finite("quaternion component %d" % i, c)
    quat = compress_quaternion(quaternion)
    pos, vel, acc, rates = fields
    return CRTPPacket(PORT_GENERIC_SETPOINT, CH_SETPOINT,
                      struct.pack("<B9hI3h", TYPE_FULL_STATE, *pos, *vel, *acc, quat, *rates))


def notify_setpoints_stop_packet(remain_valid_ms: int = 0) -> CRTPPacket:
    """Tell the Crazyflie that low-level setpoints stop, so the high-level commander takes over.

    Current firmware ignores the value; firmware before 2022.01 kept the last setpoint valid for it.
    """
    if isinstance(remain_valid_ms, bool) or not isinstance(remain_valid_ms, int) \
            or not 0 <= remain_valid_ms <= _U32_MAX:
        raise CommandValueError("remain_valid_ms must be an integer 0..%d, got %r" % (_U32_MAX, remain_valid_ms))
    return CRTPPacket(PORT_GENERIC_SETPOINT, CH_META, struct.pack("<BI", META_NOTIFY_SETPOINTS_STOP, remain_valid_ms))


class SetpointSender:
    """Sends port-7 setpoints over ``send`` (one round trip each; True when acked).

    ``protocol_version`` is set by the Crazyflie facade on connect; it picks legacy types.
    """

    def __init__(self, send, protocol_version: int = -1) -> None:
        self._send = send
        self.protocol_version = protocol_version

    def position(self, x: float, y: float, z: float, yaw_deg: float) -> bool:
        _require_generic(self.protocol_version)
        return self._send(position_packet(x, y, z, yaw_deg))

    def velocity_world(self, vx: float, vy: float, vz: float, yawrate_deg: float) -> bool:
        return self._send(velocity_world_packet(vx, vy, vz, yawrate_deg, self.protocol_version))

    def hover(self, vx: float, vy: float, yawrate_deg: float, z: float) -> bool:
        return self._send(hover_packet(vx, vy, yawrate_deg, z, self.protocol_version))

    def full_state(self, position, velocity, acceleration, quaternion, body_rates) -> bool:
        _require_generic(self.protocol_version)
        return self._send(full_state_packet(position, velocity, acceleration, quaternion, body_rates))

    def stop(self) -> bool:
        """Motors off (port 7 "stop", or a zero RPYT setpoint on firmware without port 7)."""
        return self._send(stop_packet(self.protocol_version))

    def notify_setpoints_stop(self, remain_valid_ms: int = 0) -> bool:
        _require_generic(self.protocol_version)
        return self._send(notify_setpoints_stop_packet(remain_valid_ms))
