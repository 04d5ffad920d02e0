"""Port 6 (localization): motion capture into the onboard estimator, single and packed.

Single packets carry f32 metres for one Crazyflie (unicast). Packed packets carry several
Crazyflies at once for a broadcast, as int16 millimetres keyed by the low byte of each
Crazyflie's radio address: up to 4 positions per channel-2 packet, up to 2 poses per type-9
packet. The estimator only uses them with the Kalman estimator (``stabilizer.estimator`` = 2).
"""
from __future__ import annotations

import struct
from typing import List, Sequence, Tuple

from crazyflie_driver.crtp.packet import PORT_LOCALIZATION, CRTPPacket
from crazyflie_driver.crtp.quaternion import compress_quaternion
from crazyflie_driver.errors import CommandValueError
from crazyflie_driver.protocol.checks import INT16_MAX, byte, finite, milli_int16

CH_EXTERNAL_POSITION = 0
CH_GENERIC = 1
CH_EXTERNAL_POSITION_PACKED = 2

TYPE_EMERGENCY_STOP = 3
TYPE_EMERGENCY_STOP_WATCHDOG = 4
TYPE_EXTERNAL_POSE = 8
TYPE_EXTERNAL_POSE_PACKED = 9

#: Largest |coordinate| a packed position or pose carries (m): signed 16-bit millimetres.
PACKED_RANGE_M = INT16_MAX / 1000.0
POSITIONS_PER_PACKET = 4
POSES_PER_PACKET = 2
_POSITION_ITEM = struct.Struct("<B3h")
_POSE_ITEM = struct.Struct("<B3hI")

PositionItem = Tuple[int, float, float, float]                               # id, x, y, z
PoseItem = Tuple[int, float, float, float, float, float, float, float]      # id, x, y, z, qx, qy, qz, qw


def address_id(address: bytes) -> int:
    """The identifier packed items use for a Crazyflie: the last byte of its radio address."""
    return bytes(address)[-1]


def external_position_packet(x: float, y: float, z: float) -> CRTPPacket:
    """Channel 0: one Crazyflie's position in metres."""
    return CRTPPacket(PORT_LOCALIZATION, CH_EXTERNAL_POSITION,
                      struct.pack("<3f", finite("x", x), finite("y", y), finite("z", z)))


def _quaternion(q: Sequence[float]) -> List[float]:
    if len(q) != 4:
        raise CommandValueError("a quaternion has 4 components (x, y, z, w), got %d" % len(q))
    return [finite("q" + axis, c) for axis, c in zip("xyzw", q)]


def external_pose_packet(x: float, y: float, z: float, quaternion: Sequence[float]) -> CRTPPacket:
    """Channel 1 type 8: position (m) and orientation (qx, qy, qz, qw) as f32."""
    q = _quaternion(quaternion)
    compress_quaternion(q)   # rejects a zero quaternion like the packed form does
    return CRTPPacket(PORT_LOCALIZATION, CH_GENERIC,
                      struct.pack("<B7f", TYPE_EXTERNAL_POSE, finite("x", x), finite("y", y), finite("z", z), *q))


def packed_position(position: Sequence[float]) -> Tuple[float, float, float]:
    """``position`` (x, y, z in m) as floats when a packed item can carry it, else CommandValueError
    naming the coordinate: NaN, infinity and anything beyond +-PACKED_RANGE_M do not fit. A stream
    checks each pose with this before it joins a frame, so one bad pose never sinks the others' packets."""
    if len(position) != 3:
        raise CommandValueError("a position has 3 coordinates (x, y, z), got %d" % len(position))
    for axis, value in zip("xyz", position):
        milli_int16(axis, value)
    return (float(position[0]), float(position[1]), float(position[2]))


def _chunks(items: Sequence, size: int) -> List[Sequence]:
    return [items[i:i + size] for i in range(0, len(items), size)]


def packed_position_packets(items: Sequence[PositionItem]) -> List[CRTPPacket]:
    """Channel 2 packets, 4 positions each; the last one holds what is left (fewer bytes)."""
    packets = []
    for chunk in _chunks(list(items), POSITIONS_PER_PACKET):
        data = b"".join(_POSITION_ITEM.pack(byte("id", cf), milli_int16("x", x), milli_int16("y", y),
                                            milli_int16("z", z)) for cf, x, y, z in chunk)
        packets.append(CRTPPacket(PORT_LOCALIZATION, CH_EXTERNAL_POSITION_PACKED, data))
    return packets


def packed_pose_packets(items: Sequence[PoseItem]) -> List[CRTPPacket]:
    """Channel 1 type 9 packets, 2 poses each: id, position int16 mm, compressed quaternion."""
    packets = []
    for chunk in _chunks(list(items), POSES_PER_PACKET):
        data = bytes([TYPE_EXTERNAL_POSE_PACKED])
        for cf, x, y, z, qx, qy, qz, qw in chunk:
            q = compress_quaternion(_quaternion((qx, qy, qz, qw)))
            data += _POSE_ITEM.pack(byte("id", cf), milli_int16("x", x), milli_int16("y", y), milli_int16("z", z), q)
        packets.append(CRTPPacket(PORT_LOCALIZATION, CH_GENERIC, data))
    return packets


def emergency_stop_watchdog_packet_legacy() -> CRTPPacket:
    """The e-stop watchdog keep-alive on port 6, for firmware before the supervisor port."""
    return CRTPPacket(PORT_LOCALIZATION, CH_GENERIC, bytes([TYPE_EMERGENCY_STOP_WATCHDOG]))


class LocalizationSender:
    """Unicast motion capture for one Crazyflie over ``send`` (True when acked)."""

    def __init__(self, send) -> None:
        self._send = send

    def external_position(self, x: float, y: float, z: float) -> bool:
        return self._send(external_position_packet(x, y, z))

    def external_pose(self, x: float, y: float, z: float, quaternion: Sequence[float]) -> bool:
        return self._send(external_pose_packet(x, y, z, quaternion))
